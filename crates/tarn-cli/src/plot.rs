//! The paper's Figures 6b, 7, 8a and 8b for one sensor, as four panels of one PNG.

use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;

use tarn::error::{Error, Result};
use tarn::optics::AbsorptionTable;
use tarn::optics::{Attenuation, LidarModelConfig, LidarWaterModel};

type PlotResult<T = ()> = std::result::Result<T, Box<dyn std::error::Error>>;

const FONT: &str = "sans-serif";

fn register_font() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(Error::invalid(
            "plot font",
            "the embedded DejaVu Sans font did not load",
        ))
    }
}

/// One attenuation case drawn in Figures 8a and 8b.
struct Case {
    label: String,
    model: LidarWaterModel,
    colour: RGBColor,
}

fn cases(model: &LidarWaterModel) -> Result<Vec<Case>> {
    let cfg = *model.config();
    let with = |att: Attenuation| {
        LidarWaterModel::new(LidarModelConfig {
            attenuation: att,
            ..cfg
        })
    };
    let mut out = Vec::new();
    for (label, att, colour) in [
        (
            "525 nm pure",
            Attenuation::PureWater {
                wavelength_nm: 525.0,
            },
            RGBColor(0, 150, 0),
        ),
        (
            "625 nm pure (clear)",
            Attenuation::PureWater {
                wavelength_nm: 625.0,
            },
            RGBColor(220, 0, 0),
        ),
        (
            "900 nm pure",
            Attenuation::PureWater {
                wavelength_nm: 900.0,
            },
            RGBColor(120, 0, 160),
        ),
        (
            "murky 2.2 /m",
            Attenuation::PerMetre(2.2),
            RGBColor(140, 100, 40),
        ),
    ] {
        out.push(Case {
            label: label.to_string(),
            model: with(att)?,
            colour,
        });
    }
    // The sensor's own water: mark the matching paper case, or add a black curve.
    let own = model.attenuation_per_m();
    match out
        .iter_mut()
        .find(|c| (c.model.attenuation_per_m() - own).abs() <= 1e-12 * own.max(1.0))
    {
        Some(c) => c.label.push_str(" = this sensor"),
        None => {
            let label = match cfg.attenuation {
                Attenuation::PureWater { wavelength_nm } => {
                    format!("this sensor: {wavelength_nm} nm pure")
                }
                Attenuation::PerMetre(c) => format!("this sensor: {c} /m"),
            };
            out.push(Case {
                label,
                model: model.clone(),
                colour: RGBColor(0, 0, 0),
            });
        }
    }
    Ok(out)
}

/// Draws Figures 6b (Fresnel), 7 (absorption), 8a (return ratio at `depth_m`, or 0.3 m when
/// `depth_m` is 0, as in the paper) and 8b (maximum depth) for `model`'s sensor into a PNG at
/// `path`, written to a temporary file first and renamed.
pub fn plot_lidar_model(model: &LidarWaterModel, depth_m: f64, path: &Path) -> Result<()> {
    if !(depth_m.is_finite() && depth_m >= 0.0) {
        return Err(Error::invalid(
            "water depth (m)",
            format!("{depth_m} is not ≥ 0"),
        ));
    }
    register_font()?;
    let depth = if depth_m > 0.0 { depth_m } else { 0.3 };
    let cases = cases(model)?;
    let (w, h) = (1600u32, 1200u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    draw(model, &cases, depth, &mut buf, (w, h))
        .map_err(|e| Error::invalid("plot", e.to_string()))?;
    let img = image::RgbImage::from_raw(w, h, buf)
        .ok_or_else(|| Error::invalid("plot", "image buffer has the wrong size"))?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let tmp = tempfile::Builder::new()
        .prefix(".tarn-plot")
        .suffix(".png")
        .tempfile_in(dir)
        .map_err(|e| Error::io(dir, e))?;
    {
        use image::codecs::png::{CompressionType, FilterType, PngEncoder};
        use image::ImageEncoder;
        use std::io::Write;
        let mut file = std::io::BufWriter::new(tmp.as_file());
        PngEncoder::new_with_quality(&mut file, CompressionType::Best, FilterType::Adaptive)
            .write_image(img.as_raw(), w, h, image::ExtendedColorType::Rgb8)
            .map_err(|e| Error::io(tmp.path(), std::io::Error::other(e)))?;
        file.flush().map_err(|e| Error::io(tmp.path(), e))?;
    }
    // A temporary file is private (0600); the plot is an ordinary output file.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o644))
            .map_err(|e| Error::io(tmp.path(), e))?;
    }
    tmp.persist(path).map_err(|e| Error::io(path, e.error))?;
    Ok(())
}

fn draw(
    model: &LidarWaterModel,
    cases: &[Case],
    depth: f64,
    buf: &mut [u8],
    size: (u32, u32),
) -> PlotResult {
    let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((2, 2));
    fresnel_panel(model, &panels[0])?;
    absorption_panel(model, &panels[1])?;
    return_panel(model, cases, depth, &panels[2])?;
    depth_panel(model, cases, &panels[3])?;
    root.present()?;
    Ok(())
}

fn fresnel_panel(model: &LidarWaterModel, area: &DrawingArea<BitMapBackend, Shift>) -> PlotResult {
    let h = model.config().height_m;
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "6b: Fresnel power into water (n = {})",
                model.config().n_water
            ),
            (FONT, 24),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..10.0, 0.0..100.0)?;
    chart
        .configure_mesh()
        .x_desc("lookahead / sensor height")
        .y_desc("percent of incident power")
        .label_style((FONT, 16))
        .draw()?;
    let xs: Vec<f64> = (0..=500).map(|i| i as f64 * 0.02).collect();
    let fr = |x: f64| model.transmittance(x * h).unwrap_or((0.0, 0.0));
    type Curve<'a> = (&'static str, RGBColor, Box<dyn Fn(f64) -> f64 + 'a>);
    let series: [Curve; 4] = [
        (
            "T horizontal (s)",
            RGBColor(0, 0, 200),
            Box::new(|x| 100.0 * fr(x).0),
        ),
        (
            "T vertical (p)",
            RGBColor(200, 0, 0),
            Box::new(|x| 100.0 * fr(x).1),
        ),
        (
            "R horizontal (s)",
            RGBColor(100, 100, 255),
            Box::new(|x| 100.0 * (1.0 - fr(x).0)),
        ),
        (
            "R vertical (p)",
            RGBColor(255, 120, 120),
            Box::new(|x| 100.0 * (1.0 - fr(x).1)),
        ),
    ];
    for (label, colour, f) in series {
        chart
            .draw_series(LineSeries::new(
                xs.iter().map(|&x| (x, f(x))),
                colour.stroke_width(2),
            ))?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::MiddleRight)
        .label_font((FONT, 16))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

fn absorption_panel(
    model: &LidarWaterModel,
    area: &DrawingArea<BitMapBackend, Shift>,
) -> PlotResult {
    let mut chart = ChartBuilder::on(area)
        .caption("7: absorption of pure water and ice", (FONT, 24))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(200.0..2000.0, (1e-4..1e5).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("wavelength (nm)")
        .y_desc("absorption coefficient (1/m)")
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .label_style((FONT, 16))
        .draw()?;
    for (table, label, colour) in [
        (
            AbsorptionTable::Water,
            "water, Segelstein 1981",
            RGBColor(0, 0, 200),
        ),
        (
            AbsorptionTable::Ice,
            "ice, Warren & Brandt 2008",
            RGBColor(0, 170, 200),
        ),
    ] {
        chart
            .draw_series(LineSeries::new(
                table.samples().filter(|s| s.0 >= 200.0 && s.0 <= 2000.0),
                colour.stroke_width(2),
            ))?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
    }
    let mut marks: Vec<(f64, f64, String)> = Vec::new();
    for wl in [525.0, 625.0, 900.0, 1550.0] {
        if let Ok(a) = tarn::optics::absorption_per_m(wl) {
            marks.push((wl, a, format!("{wl:.0} nm: {a:.3} /m")));
        }
    }
    marks.push((575.0, 2.2, "murky lake 575 nm: 2.2 /m".to_string()));
    chart.draw_series(marks.iter().map(|(x, y, s)| {
        EmptyElement::at((*x, *y))
            + Circle::new((0, 0), 5, RED.filled())
            + Text::new(s.clone(), (8, -8), (FONT, 15))
    }))?;
    if let Attenuation::PureWater { wavelength_nm } = model.config().attenuation {
        let a = model.attenuation_per_m();
        chart.draw_series(std::iter::once(
            EmptyElement::at((wavelength_nm, a))
                + Rectangle::new([(-6, -6), (6, 6)], BLACK.stroke_width(2))
                + Text::new(
                    format!("this sensor {wavelength_nm} nm"),
                    (8, 6),
                    (FONT, 15),
                ),
        ))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font((FONT, 16))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

fn lookahead_axis_end(model: &LidarWaterModel) -> f64 {
    (model
        .dry_limit()
        .unwrap_or(model.config().height_m)
        .max(1.0)
        * 1.1)
        .ceil()
}

fn return_panel(
    model: &LidarWaterModel,
    cases: &[Case],
    depth: f64,
    area: &DrawingArea<BitMapBackend, Shift>,
) -> PlotResult {
    let x_end = lookahead_axis_end(model);
    let p = model.min_power_ratio();
    let top = model.dry_ratio(0.0).unwrap_or(1.0) * 10.0;
    let bottom = (p * 1e-4).min(top * 1e-8);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "8a: return / output power, {depth} m deep, sensor {} m high",
                model.config().height_m
            ),
            (FONT, 24),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..x_end, (bottom..top).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("lookahead (m)")
        .y_desc("power ratio")
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .label_style((FONT, 16))
        .draw()?;
    let xs: Vec<f64> = (0..=600).map(|i| x_end * i as f64 / 600.0).collect();
    let clamp = |v: f64| v.max(bottom);
    for c in cases {
        let colour = c.colour;
        chart
            .draw_series(LineSeries::new(
                xs.iter()
                    .map(|&x| (x, clamp(c.model.return_ratio(x, depth).unwrap_or(0.0)))),
                colour.stroke_width(2),
            ))?
            .label(c.label.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
    }
    let grey = RGBColor(120, 120, 120);
    chart
        .draw_series(LineSeries::new(
            xs.iter()
                .map(|&x| (x, clamp(model.dry_ratio(x).unwrap_or(0.0)))),
            grey.stroke_width(2),
        ))?
        .label("dry ground")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], grey.stroke_width(2)));
    chart
        .draw_series(DashedLineSeries::new(
            [(0.0, p), (x_end, p)],
            8,
            6,
            BLACK.stroke_width(1),
        ))?
        .label(format!("minimum detectable {p:.2e}"))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

fn depth_panel(
    model: &LidarWaterModel,
    cases: &[Case],
    area: &DrawingArea<BitMapBackend, Shift>,
) -> PlotResult {
    let x_end = lookahead_axis_end(model);
    let xs: Vec<f64> = (0..=600).map(|i| x_end * i as f64 / 600.0).collect();
    let curves: Vec<Vec<(f64, f64)>> = cases
        .iter()
        .map(|c| {
            xs.iter()
                .map(|&x| (x, c.model.max_depth(x).unwrap_or(0.0)))
                .collect()
        })
        .collect();
    // Clear water can reach tens of metres straight down; keep the axis readable.
    let y_max = curves
        .iter()
        .flatten()
        .filter(|p| p.0 >= 1.0)
        .map(|p| p.1)
        .fold(0.5f64, f64::max)
        .min(5.0);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("8b: greatest depth with a bottom return (axis cut at {y_max:.1} m)"),
            (FONT, 24),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..x_end, 0.0..y_max * 1.05)?;
    chart
        .configure_mesh()
        .x_desc("lookahead (m)")
        .y_desc("water depth (m)")
        .label_style((FONT, 16))
        .draw()?;
    for (c, pts) in cases.iter().zip(curves) {
        let colour = c.colour;
        chart
            .draw_series(LineSeries::new(
                pts.into_iter().map(|(x, y)| (x, y.min(y_max * 1.05))),
                colour.stroke_width(2),
            ))?
            .label(c.label.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
    }
    if let Some(dry) = model.dry_limit() {
        let grey = RGBColor(120, 120, 120);
        chart
            .draw_series(DashedLineSeries::new(
                [(dry, 0.0), (dry, y_max)],
                8,
                6,
                grey.stroke_width(2),
            ))?
            .label(format!("dry ground lost at {dry:.1} m"))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], grey.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}
