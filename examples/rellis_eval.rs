//! Tables for the README: colour classifiers on the real RELLIS-3D puddle frame (trained on
//! the left half, scored on the right half), each lookup-table size against direct mixture
//! evaluation, and the image's water labels projected onto the frame's Ouster scan.
//!
//! `cargo run --release --example rellis_eval` (reads ../shared/data).

#[path = "../tests/rellis_common.rs"]
mod rellis_common;

use std::time::Instant;

use rellis_common::*;
use tarn::classify::{
    ColorLut, ColorModel, Confusion, Label, LabelImage, RuleClassifier, TrainConfig,
};

fn row(name: &str, c: &Confusion) {
    println!(
        "| {name} | {:.3} | {:.3} | {:.3} |",
        c.precision(),
        c.recall(),
        c.iou()
    );
}

fn main() {
    if !available() {
        return;
    }
    let r = load();
    let t = Instant::now();
    let cfg = TrainConfig::default();
    let model = train(&r, &cfg);
    println!(
        "trained on the left half in {:.2} s (wall clock, one run)",
        t.elapsed().as_secs_f64()
    );
    for c in &model.data().classes {
        println!(
            "  {}: prior {:.3}, {} components",
            c.name,
            c.prior,
            c.components.len()
        );
    }
    let hz = horizon(&r);
    let above = hz.above_mask(r.camera.width, r.camera.height).unwrap();
    let with_h = |l: &LabelImage| {
        let mut l = l.clone();
        hz.apply(&mut l, true).unwrap();
        l
    };

    classifier_table(&r, &model, &with_h);
    mixture_table(&r, &with_h);
    let l6 = with_h(&ColorLut::compile(&model, 6).unwrap().classify(&r.rgb));
    error_tables(&r, &l6, &above);
    projection_tables(&r, &l6);
}

/// Precision, recall and IoU of each classifier on the right half of the image.
fn classifier_table(r: &Rellis, model: &ColorModel, with_h: &dyn Fn(&LabelImage) -> LabelImage) {
    println!("\nRight half of the image, puddle (id 31) as truth:\n");
    println!("| classifier | precision | recall | IoU |\n| --- | --- | --- | --- |");
    let rule = RuleClassifier::default().classify(&r.rgb);
    row("rule, paper Table 1", &score_right(&rule, &r.ids));
    row("rule + horizon", &score_right(&with_h(&rule), &r.ids));
    let direct = model.classify(&r.rgb);
    row("GMM direct", &score_right(&direct, &r.ids));
    row(
        "GMM direct + horizon",
        &score_right(&with_h(&direct), &r.ids),
    );
    for bits in [3u8, 4, 5, 6, 7, 8] {
        let lut = ColorLut::compile(model, bits).unwrap();
        let l = lut.classify(&r.rgb);
        let agree = l
            .data
            .iter()
            .zip(&direct.data)
            .filter(|(a, b)| a == b)
            .count() as f64
            / l.data.len() as f64;
        row(
            &format!(
                "LUT {bits} bits ({} B) + horizon, agrees with direct on {:.2} % of pixels",
                lut.table_bytes(),
                100.0 * agree
            ),
            &score_right(&with_h(&l), &r.ids),
        );
    }
}

/// Speed against error of the mixture size.
fn mixture_table(r: &Rellis, with_h: &dyn Fn(&LabelImage) -> LabelImage) {
    // Where the errors are: the puddle polygon covers wet mud between the puddles.
    // Speed against error of the mixture size: BIC picks 1..=k components per class; the
    // time is training (left half) and direct classification of the whole image (the
    // lookup table costs the same for every model).
    println!("\nMixture components (speed against error), right half, + horizon:\n");
    println!("| max components k | components (water/sky/other) | train s | direct classify ms | precision | recall | IoU |\n| ---: | --- | ---: | ---: | ---: | ---: | ---: |");
    for k in [1usize, 2, 4, 6, 8] {
        let t = Instant::now();
        let m = train(
            r,
            &TrainConfig {
                max_components: k,
                ..TrainConfig::default()
            },
        );
        let train_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let l = m.classify(&r.rgb);
        let classify_ms = t.elapsed().as_secs_f64() * 1e3;
        let c = score_right(&with_h(&l), &r.ids);
        let sizes: Vec<String> = m
            .data()
            .classes
            .iter()
            .map(|c| c.components.len().to_string())
            .collect();
        println!(
            "| {k} | {} | {train_s:.2} | {classify_ms:.1} | {:.3} | {:.3} | {:.3} |",
            sizes.join("/"),
            c.precision(),
            c.recall(),
            c.iou()
        );
    }
}

/// Where the errors are: the pixels inside the puddle polygon, and the pixels called water
/// by image class id.
fn error_tables(r: &Rellis, l6: &LabelImage, above: &[bool]) {
    let (mut bright, mut bright_hit, mut dark, mut dark_hit) = (0u64, 0u64, 0u64, 0u64);
    let w = r.ids.width();
    for (i, (p, id)) in r.rgb.pixels().zip(r.ids.pixels()).enumerate() {
        if id.0[0] != PUDDLE || !in_half(i as u32 % w, w, false) {
            continue;
        }
        let b = tarn::classify::brightness(p.0);
        let s = tarn::classify::saturation(p.0);
        let water = l6.data[i] == Label::Water;
        if b > 150.0 && s < 0.25 {
            bright += 1;
            bright_hit += water as u64;
        } else {
            dark += 1;
            dark_hit += water as u64;
        }
    }
    println!(
        "\nInside the right-half puddle polygon: {bright} sky-like pixels (I > 150, S < 0.25), {:.1} % called water; {dark} other pixels (wet mud, ruts), {:.1} % called water.",
        100.0 * bright_hit as f64 / bright.max(1) as f64,
        100.0 * dark_hit as f64 / dark.max(1) as f64
    );
    // False positives by image class id (right half).
    let mut fp_by: std::collections::BTreeMap<u8, (u64, u64)> = Default::default();
    for (i, id) in r.ids.pixels().enumerate() {
        if in_half(i as u32 % w, w, false) {
            let e = fp_by.entry(id.0[0]).or_default();
            e.0 += 1;
            e.1 += (l6.data[i] == Label::Water) as u64;
        }
    }
    println!("\nRight half, GMM LUT 6 bits + horizon, pixels called water by image class id:\n");
    println!("| id | pixels | called water |\n| --- | --- | --- |");
    for (id, (n, wtr)) in &fp_by {
        println!(
            "| {id} | {n} | {wtr} ({:.1} %) |",
            100.0 * *wtr as f64 / *n as f64
        );
    }
    let sky_total = r.ids.pixels().filter(|id| id.0[0] == SKY).count();
    let sky_above = r
        .ids
        .pixels()
        .zip(above)
        .filter(|(id, a)| id.0[0] == SKY && **a)
        .count();
    println!(
        "Horizon from the lidar ground plane: {sky_above} of {sky_total} sky pixels above it."
    );
}

/// The image labels projected onto the Ouster scan, against the scan's own labels.
fn projection_tables(r: &Rellis, l6: &LabelImage) {
    // Projection onto the Ouster scan.
    let (per_point, votes) =
        tarn::project::label_points(l6, &r.camera, &r.cloud, &r.lidar_to_cam, 0.25).unwrap();
    let mut c = Confusion::default();
    let mut truth_img = Confusion::default();
    let pix = lidar_pixels(r, &r.lidar_to_cam);
    for (i, l) in per_point.iter().enumerate() {
        if let Some(l) = l {
            c.add(*l == Label::Water, r.lidar_ids[i] == 31);
        }
    }
    for (i, id) in &pix {
        truth_img.add(*id == PUDDLE, r.lidar_ids[*i] == 31);
    }
    println!(
        "\nOuster points that project into the image: {}; scan puddle points among them: {}\n",
        pix.len(),
        c.tp + c.fn_
    );
    println!("| image labels projected onto the scan, vs the scan's class 31 | precision | recall | IoU |\n| --- | --- | --- | --- |");
    row("GMM LUT 6 bits + horizon", &c);
    row(
        "the image's own puddle polygon (calibration check)",
        &truth_img,
    );
    // Cells: majority label of the votes vs cells holding a scan puddle point.
    let mut cells = Confusion::default();
    let mut puddle_cells = std::collections::HashSet::new();
    for (i, id) in r.lidar_ids.iter().enumerate() {
        if *id == 31 && per_point[i].is_some() {
            let p = r.cloud.point_in_map(i);
            puddle_cells.insert(tarn::grid::key_of(0.25, p.x, p.y));
        }
    }
    for (k, _) in votes.to_sorted_vec() {
        cells.add(
            votes.majority(k) == Some(Label::Water),
            puddle_cells.contains(&k),
        );
    }
    row(
        "0.25 m cells: majority vote vs cell holds a class-31 point",
        &cells,
    );
}
