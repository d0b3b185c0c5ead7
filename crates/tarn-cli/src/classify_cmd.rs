//! `tarn train-colour` and `tarn classify`: the colour water classifier on images.

use std::collections::HashMap;
use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;
use serde::Deserialize;
use serde_json::json;
use tarn::classify::{
    optical_pose, save_gray_png, training_samples, ColorLut, ColorModel, Horizon, Label,
    RuleClassifier, TrainConfig,
};
use tarn::geom::{pose_xyz_rpy, CameraModel, Distortion};

fn parse_list<T: std::str::FromStr>(
    s: &str,
    what: &str,
    n: Option<usize>,
) -> anyhow::Result<Vec<T>> {
    let v: Vec<T> = s
        .split(',')
        .map(|x| {
            x.trim()
                .parse::<T>()
                .map_err(|_| anyhow::anyhow!("{what}: {x:?} is not a number"))
        })
        .collect::<anyhow::Result<_>>()?;
    if let Some(n) = n {
        if v.len() != n {
            bail!(
                "{what}: expected {n} comma-separated numbers, got {}",
                v.len()
            );
        }
    }
    Ok(v)
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
pub struct TrainArgs {
    /// RGB image (PNG or JPEG).
    #[arg(long)]
    image: PathBuf,
    /// Label image of class ids (8-bit PNG, same size).
    #[arg(long)]
    labels: PathBuf,
    /// Class ids that are water, comma-separated.
    #[arg(long)]
    water_ids: String,
    /// Class ids that are sky (otherwise they count as not-water).
    #[arg(long)]
    sky_ids: Option<String>,
    /// Class ids that are snow or ice.
    #[arg(long)]
    snow_ids: Option<String>,
    /// Only pixels in x0,y0,x1,y1 (x1, y1 exclusive).
    #[arg(long)]
    region: Option<String>,
    /// Largest number of mixture components per class (BIC chooses 1..=this).
    #[arg(long, default_value_t = 6)]
    max_components: usize,
    /// Output model (JSON).
    #[arg(long)]
    out: PathBuf,
    /// Print what was trained (pixels per class, components, the BIC table) as one JSON
    /// object instead of text.
    #[arg(long)]
    json: bool,
}

pub fn train(a: TrainArgs) -> anyhow::Result<()> {
    let rgb = image::open(&a.image)
        .with_context(|| a.image.display().to_string())?
        .to_rgb8();
    let ids = image::open(&a.labels).with_context(|| a.labels.display().to_string())?;
    if ids.color() != image::ColorType::L8 {
        bail!(
            "{}: label image must be 8-bit grey (class ids), it is {:?}",
            a.labels.display(),
            ids.color()
        );
    }
    let ids = ids.to_luma8();
    let mut class_of = HashMap::new();
    for (list, label) in [
        (Some(&a.water_ids), Label::Water),
        (a.sky_ids.as_ref(), Label::Sky),
        (a.snow_ids.as_ref(), Label::SnowIce),
    ] {
        if let Some(s) = list {
            for id in parse_list::<u8>(s, "class ids", None)? {
                if class_of.insert(id, label).is_some() {
                    bail!("class id {id} is given twice");
                }
            }
        }
    }
    let region = match &a.region {
        Some(s) => {
            let v = parse_list::<u32>(s, "--region", Some(4))?;
            Some([v[0], v[1], v[2], v[3]])
        }
        None => None,
    };
    let samples = training_samples(&rgb, &ids, region, &class_of)
        .with_context(|| a.labels.display().to_string())?;
    if !samples.iter().any(|(l, _)| *l == Label::Water) {
        bail!(
            "no pixel of the water ids {} in the training region",
            a.water_ids
        );
    }
    let refs: Vec<(Label, &[[u8; 3]])> = samples.iter().map(|(l, v)| (*l, v.as_slice())).collect();
    let cfg = TrainConfig {
        max_components: a.max_components,
        ..Default::default()
    };
    let (model, report) = ColorModel::train(&refs, &cfg)?;
    model.save(&a.out)?;
    let samples_of = |label: Label| {
        report
            .samples
            .iter()
            .find(|(l, _, _)| *l == label)
            .map_or((0, 0), |&(_, n, d)| (n, d))
    };
    if a.json {
        let classes: Vec<_> = model
            .data()
            .classes
            .iter()
            .map(|c| {
                let (pixels, colours) = samples_of(c.label);
                json!({"class": c.name, "pixels": pixels, "colours": colours,
                       "prior": c.prior, "components": c.components.len()})
            })
            .collect();
        let bic: Vec<_> = report
            .bic
            .iter()
            .map(|r| {
                json!({"class": format!("{:?}", r.label).to_lowercase(), "components": r.components,
                       "log_likelihood": r.log_likelihood, "bic": r.bic, "iterations": r.iterations})
            })
            .collect();
        let out = json!({"model": a.out, "classes": classes, "bic": bic});
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    for c in &model.data().classes {
        let (n, d) = samples_of(c.label);
        println!(
            "{:<8} {:>9} pixels {:>7} colours  prior {:.3}  {} components",
            c.name,
            n,
            d,
            c.prior,
            c.components.len()
        );
    }
    for r in &report.bic {
        println!(
            "  {:<8} k={} ln L {:>14.1}  BIC {:>14.1}  ({} EM iterations)",
            format!("{:?}", r.label).to_lowercase(),
            r.components,
            r.log_likelihood,
            r.bic,
            r.iterations
        );
    }
    println!("wrote {}", a.out.display());
    Ok(())
}

/// Camera intrinsics as JSON (the fields of a ROS CameraInfo that matter).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraInfoJson {
    width: usize,
    height: usize,
    /// fx, fy, cx, cy.
    k: [f64; 4],
    #[serde(default)]
    distortion_model: String,
    #[serde(default)]
    d: Vec<f64>,
}

fn load_camera(p: &PathBuf) -> anyhow::Result<CameraModel> {
    let text = std::fs::read_to_string(p).with_context(|| p.display().to_string())?;
    let c: CameraInfoJson = serde_json::from_str(&text).with_context(|| format!("{}: not camera info JSON ({{width, height, k: [fx, fy, cx, cy], distortion_model, d}})", p.display()))?;
    let dist = match (c.distortion_model.as_str(), c.d.len()) {
        ("" | "none", 0) => Distortion::None,
        ("plumb_bob", 5) => Distortion::PlumbBob([c.d[0], c.d[1], c.d[2], c.d[3], c.d[4]]),
        ("equidistant", 4) => Distortion::Equidistant([c.d[0], c.d[1], c.d[2], c.d[3]]),
        (m, n) => bail!(
            "{}: distortion model {m:?} with {n} coefficients (plumb_bob needs 5, equidistant 4)",
            p.display()
        ),
    };
    CameraModel::new(c.width, c.height, c.k, dist, "camera")
        .with_context(|| p.display().to_string())
}

#[derive(Args)]
#[command(allow_negative_numbers = true)]
pub struct ClassifyArgs {
    /// RGB image (PNG or JPEG).
    image: PathBuf,
    /// Colour model from `tarn train-colour`; without it, the rule baseline of the paper's
    /// Table 1.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Water mask to write (8-bit PNG, 255 = water, 0 = not water).
    #[arg(long)]
    out: PathBuf,
    /// Also write all labels (8-bit PNG: 0 other, 1 water, 2 sky, 3 snow/ice, 255 unknown).
    #[arg(long)]
    labels_out: Option<PathBuf>,
    /// Bits per channel of the lookup table the model is compiled into (1..=8).
    #[arg(long, default_value_t = 6)]
    lut_bits: u8,
    /// Rows above this one are above the horizon (sky, never water).
    #[arg(long, conflicts_with_all = ["camera_info", "camera_pose"])]
    horizon_row: Option<usize>,
    /// Camera intrinsics JSON {width, height, k: [fx, fy, cx, cy], distortion_model, d}.
    #[arg(long, requires = "camera_pose")]
    camera_info: Option<PathBuf>,
    /// Camera body pose in the map frame: x,y,z,roll,pitch,yaw (metres, radians; body axes
    /// x forward, y left, z up).
    #[arg(long, requires = "camera_info", allow_hyphen_values = true)]
    camera_pose: Option<String>,
    /// Keep sky-coloured pixels below the horizon as sky (default: they are sky reflections,
    /// i.e. water).
    #[arg(long)]
    keep_sky_below_horizon: bool,
    /// Print the class fractions (and the horizon's changes) as one JSON object instead of
    /// text.
    #[arg(long)]
    json: bool,
}

pub fn classify(a: ClassifyArgs) -> anyhow::Result<()> {
    let rgb = image::open(&a.image)
        .with_context(|| a.image.display().to_string())?
        .to_rgb8();
    let mut labels = match &a.model {
        Some(p) => ColorLut::compile(&ColorModel::load(p)?, a.lut_bits)?.classify(&rgb),
        None => RuleClassifier::default().classify(&rgb),
    };
    let horizon = match (a.horizon_row, &a.camera_info, &a.camera_pose) {
        (Some(r), _, _) => Some(Horizon::Row(r)),
        (None, Some(ci), Some(pose)) => {
            let v = parse_list::<f64>(pose, "--camera-pose", Some(6))?;
            Some(Horizon::Camera {
                camera: load_camera(ci)?,
                cam_to_map: optical_pose(&pose_xyz_rpy(v[0], v[1], v[2], v[3], v[4], v[5])),
            })
        }
        _ => None,
    };
    let horizon = match horizon {
        Some(h) => Some(
            h.apply(&mut labels, !a.keep_sky_below_horizon)
                .with_context(|| a.image.display().to_string())?,
        ),
        None => None,
    };
    save_gray_png(&a.out, &labels.water_mask()?)?;
    if let Some(p) = &a.labels_out {
        save_gray_png(p, &labels.to_gray()?)?;
    }
    let n = labels.data.len().max(1);
    let fraction = |l: Label| labels.data.iter().filter(|&&x| x == l).count() as f64 / n as f64;
    if a.json {
        let out = json!({
            "image": a.image, "mask": a.out, "labels": a.labels_out,
            "pixels": labels.data.len(),
            "water": fraction(Label::Water), "sky": fraction(Label::Sky),
            "snow_ice": fraction(Label::SnowIce), "other": fraction(Label::Other),
            "horizon": horizon.map(|st| json!({"above": st.above, "water_to_sky": st.water_to_sky,
                                                "sky_to_water": st.sky_to_water})),
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    if let Some(st) = horizon {
        println!(
            "horizon: {} pixels above; {} water → sky, {} sky → water",
            st.above, st.water_to_sky, st.sky_to_water
        );
    }
    println!(
        "{}: water {:.1} %, sky {:.1} %, other {:.1} %",
        a.image.display(),
        100.0 * fraction(Label::Water),
        100.0 * fraction(Label::Sky),
        100.0 * fraction(Label::Other)
    );
    println!("wrote {}", a.out.display());
    Ok(())
}
