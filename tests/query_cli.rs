//! `splatraj query` end to end: the labels, region and features routes, the text and JSON
//! reports, the highlighted picture, and clean failures (with suggestions) that write nothing.

mod common;

use common::{assert_clean_failure, s, splatraj, stderr, stdout};

use std::path::{Path, PathBuf};
use std::process::Output;

use serde_json::{Value, json};
use splatraj_scene::demo::demo_layout;
use splatraj_scene::{ReadOptions, Scene, read_scene};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("crates/splatraj-scene/tests/data")
        .join(name)
}

fn fruit() -> (PathBuf, PathBuf) {
    (
        data("fruit_drops_minimal.ply"),
        data("fruit_drops_minimal.json"),
    )
}

fn fruit_scene() -> Scene {
    let (ply, sidecar) = fruit();
    let options = ReadOptions {
        labels: Some(sidecar),
        ..ReadOptions::default()
    };
    read_scene(&ply, &options).unwrap().scene
}

/// A 50 000-Gaussian demo scene in `dir`.
fn demo(dir: &Path) -> PathBuf {
    let ply = dir.join("demo.ply");
    let out = splatraj(&["scene", "demo", "--gaussians", "50000", "--out", s(&ply)]);
    assert!(out.status.success(), "{}", stderr(&out));
    ply
}

fn json_report(out: &Output) -> Value {
    assert!(out.status.success(), "{}", stderr(out));
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("stdout is not one JSON object ({e}): {}", stdout(out)))
}

/// Pixels that are clearly the magenta highlight (red and blue well above green).
fn magenta_centroid(png: &Path, width: u32, height: u32) -> (f64, f64, usize) {
    let image = image::open(png).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), (width, height));
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
    for (x, y, p) in image.enumerate_pixels() {
        let [r, g, b] = p.0.map(i32::from);
        if r - g > 90 && b - g > 60 {
            sx += f64::from(x);
            sy += f64::from(y);
            n += 1;
        }
    }
    assert!(n > 0, "no highlighted pixel in {}", png.display());
    (sx / n as f64, sy / n as f64, n)
}

fn assert_in_middle_third(png: &Path, width: u32, height: u32) {
    let (x, y, n) = magenta_centroid(png, width, height);
    let (w, h) = (f64::from(width), f64::from(height));
    assert!(
        (w / 3.0..2.0 * w / 3.0).contains(&x) && (h / 3.0..2.0 * h / 3.0).contains(&y),
        "highlight centroid ({x:.1}, {y:.1}) of {n} pixels is not in the middle third of \
         {width}×{height}"
    );
}

#[test]
fn label_query_counts_exactly_and_pictures_the_object() {
    let (ply, sidecar) = fruit();
    let dir = tempfile::tempdir().unwrap();
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--labels",
        s(&sidecar),
        "--query",
        "Category 4",
        "--out",
        s(dir.path()),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    // 1038: counted independently with Python from the sidecar.
    assert!(text.contains("selected: 1038 of 4721 Gaussians"), "{text}");
    for key in [
        "candidates:",
        "clustering: none",
        "kept: 1 cluster(s) [1038]",
        "dropped: 0 candidates",
        "relevancy of the 1038 selected Gaussians: min 1.0000",
        "centre:",
        "extent:",
    ] {
        assert!(text.contains(key), "{key} missing from {text}");
    }
    assert_in_middle_third(&dir.path().join("query.png"), 320, 240);

    // Case and spacing do not matter; --json prints one object.
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--labels",
        s(&sidecar),
        "--query",
        "  category   4 ",
        "--json",
        "--width",
        "160",
        "--height",
        "100",
        "--out",
        s(dir.path()),
    ]);
    let report = json_report(&out);
    assert_eq!(report["count"], 1038);
    assert_eq!(report["gaussians"], 4721);
    assert_eq!(report["name"], "Category 4");
    assert_eq!(report["source"], "labels");
    assert_eq!(report["clusters"].as_array().unwrap().len(), 1);
    assert_eq!(report["clusters"][0]["count"], 1038);
    assert_eq!(report["clusters"][0]["kept"], true);
    assert_eq!(report["rejected"], 0);
    assert_eq!(report["warnings"], json!([]));
    assert!((report["fraction"].as_f64().unwrap() - 1038.0 / 4721.0).abs() < 1e-9);
    assert_eq!(report["selected_relevancy"]["min"], 1.0);
    assert!(
        report["highlighted_share"].as_f64().unwrap() > 0.0,
        "{report}"
    );
    // The selection's centre is the per-axis median of the label's centres.
    let scene = fruit_scene();
    let labels = scene.extras.labels.as_ref().unwrap();
    for k in 0..3 {
        let mut v: Vec<f32> = (0..scene.len())
            .filter(|&i| labels.ids[i] == 4)
            .map(|i| scene.means[i][k])
            .collect();
        v.sort_by(f32::total_cmp);
        let centre = report["centre"][k].as_f64().unwrap();
        assert!(
            (centre - f64::from(v[v.len() / 2])).abs() < 0.01,
            "axis {k}: {centre} vs median {}",
            v[v.len() / 2]
        );
    }
    assert_in_middle_third(&dir.path().join("query.png"), 160, 100);
}

#[test]
fn demo_object_by_name_and_synonym() {
    let dir = tempfile::tempdir().unwrap();
    let ply = demo(dir.path());
    let out_dir = dir.path().join("out");
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--query",
        "coffee cup",
        "--synonym",
        "red mug=coffee cup,cup",
        "--json",
        "--out",
        s(&out_dir),
    ]);
    let report = json_report(&out);
    assert_eq!(report["name"], "red mug");
    // The mask is exactly the label's Gaussians.
    let scene = read_scene(&ply, &ReadOptions::default()).unwrap().scene;
    let labels = scene.extras.labels.as_ref().unwrap();
    let mug_id = demo_layout()
        .into_iter()
        .find(|o| o.name == "red mug")
        .unwrap()
        .id;
    let expected = labels.ids.iter().filter(|&&id| id == mug_id).count();
    assert_eq!(report["count"].as_u64().unwrap() as usize, expected);
    let mug = demo_layout()
        .into_iter()
        .find(|o| o.name == "red mug")
        .unwrap();
    for k in 0..3 {
        let c = report["centre"][k].as_f64().unwrap();
        assert!(
            (c - f64::from(mug.center[k])).abs() < f64::from(mug.size[k]) * 0.5,
            "centre {c} outside the mug's box on axis {k}"
        );
    }
    // Looked at from above, with the preferred view (the mug is in plain sight).
    assert_eq!(report["camera"]["elevation_degrees"], 30.0);
    assert_in_middle_third(&out_dir.join("query.png"), 320, 240);
}

#[test]
fn region_query_selects_the_box() {
    let (ply, sidecar) = fruit();
    let dir = tempfile::tempdir().unwrap();
    let (min, max) = ([0.5f32, 0.0, -2.3], [0.75f32, 0.15, -2.0]);
    let spec = format!(
        "{},{},{},{},{},{}",
        min[0], min[1], min[2], max[0], max[1], max[2]
    );
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--labels",
        s(&sidecar),
        "--box",
        &spec,
        "--query",
        "left half",
        "--json",
        "--out",
        s(dir.path()),
    ]);
    let report = json_report(&out);
    let scene = fruit_scene();
    let inside = scene
        .means
        .iter()
        .filter(|m| (0..3).all(|k| min[k] <= m[k] && m[k] <= max[k]))
        .count();
    assert!(inside > 0);
    assert_eq!(report["source"], "region");
    assert_eq!(report["name"], "left half");
    assert_eq!(report["count"].as_u64().unwrap() as usize, inside);
    assert!(dir.path().join("query.png").is_file());

    // A sphere too, and a bad one is refused before anything is read or written.
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--sphere",
        "0.75,0.11,-2.12,0.05",
        "--query",
        "middle",
        "--json",
        "--out",
        s(dir.path()),
    ]);
    assert!(json_report(&out)["count"].as_u64().unwrap() > 0);
    // A value starting with '-' is the option's value, not a flag (no '=' needed).
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--sphere",
        "-0.75,0.11,-2.12,5",
        "--up",
        "0,0,-2",
        "--query",
        "wide",
        "--json",
        "--out",
        s(dir.path()),
    ]);
    let report = json_report(&out);
    assert!(report["count"].as_u64().unwrap() > 0);
    // --up is taken as given (normalised), not guessed.
    assert_eq!(report["camera"]["up"], serde_json::json!([0.0, 0.0, -1.0]));
    assert_eq!(report["camera"]["up_from"], "config");
    let none = dir.path().join("none");
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--sphere",
        "0.75,0.11,-2.12",
        "--query",
        "middle",
        "--out",
        s(&none),
    ]);
    assert_clean_failure(&out, &["--sphere", "4"]);
    assert!(!none.exists());
}

#[test]
fn misspelt_label_fails_with_suggestions_and_writes_nothing() {
    let (ply, sidecar) = fruit();
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("out");
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--labels",
        s(&sidecar),
        "--query",
        "Categroy 4",
        "--out",
        s(&out_dir),
    ]);
    assert_clean_failure(&out, &["Categroy 4", "closest", "\"Category 4\""]);
    assert!(!out_dir.exists());

    // No labels and no other data: the error says which options are needed.
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--query",
        "Category 4",
        "--out",
        s(&out_dir),
    ]);
    assert_clean_failure(&out, &["--labels", "--phrases", "--box"]);
    assert!(!out_dir.exists());
}

/// One-hot features by label (9 labels) plus one dimension for the negatives.
fn write_features(dir: &Path, scene: &Scene) -> PathBuf {
    write_features_as(dir, scene, |_, id| id as usize)
}

/// One-hot features, Gaussian `i` with label `id` getting dimension `dimension(i, id)`.
fn write_features_as(
    dir: &Path,
    scene: &Scene,
    dimension: impl Fn(usize, i32) -> usize,
) -> PathBuf {
    use npyz::WriterBuilder;
    let labels = scene.extras.labels.as_ref().unwrap();
    let dim = 10;
    let path = dir.join("features.npy");
    let mut bytes = Vec::new();
    let mut writer = npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(&[scene.len() as u64, dim as u64])
        .writer(&mut bytes)
        .begin_nd()
        .unwrap();
    for (i, &id) in labels.ids.iter().enumerate() {
        let mut row = vec![0.0f32; dim];
        row[dimension(i, id)] = 1.0;
        writer.extend(row).unwrap();
    }
    writer.finish().unwrap();
    std::fs::write(&path, bytes).unwrap();
    path
}

fn one_hot(k: usize) -> Vec<f32> {
    let mut v = vec![0.0; 10];
    v[k] = 1.0;
    v
}

#[test]
fn features_route_selects_the_phrases_label() {
    let (ply, sidecar) = fruit();
    let dir = tempfile::tempdir().unwrap();
    let scene = fruit_scene();
    let features = write_features(dir.path(), &scene);
    let table = dir.path().join("table.json");
    let negative = one_hot(9);
    std::fs::write(
        &table,
        json!({
            "apple": one_hot(3),
            "banana": one_hot(5),
            "object": negative, "things": negative, "stuff": negative, "texture": negative,
        })
        .to_string(),
    )
    .unwrap();
    let label3 = scene
        .extras
        .labels
        .as_ref()
        .unwrap()
        .ids
        .iter()
        .filter(|&&id| id == 3)
        .count();
    assert_eq!(label3, 398);

    // Without DBSCAN: exactly label 3, with the same centre as the label query.
    let query = |extra: &[&str]| {
        let mut args = vec![
            "query",
            "--scene",
            s(&ply),
            "--labels",
            s(&sidecar),
            "--json",
            "--out",
            s(dir.path()),
        ];
        args.extend_from_slice(extra);
        splatraj(&args)
    };
    let by_features = json_report(&query(&[
        "--features",
        s(&features),
        "--phrases",
        s(&table),
        "--query",
        "apple",
        "--no-cluster",
    ]));
    assert_eq!(by_features["source"], "features");
    assert_eq!(by_features["count"], 398);
    let by_label = json_report(&query(&["--query", "Category 3"]));
    assert_eq!(by_features["centre"], by_label["centre"]);
    assert_eq!(by_features["extent"], by_label["extent"]);
    assert!(by_features["selected_relevancy"]["min"].as_f64().unwrap() > 0.99);

    // With clustering (the default): the main part of label 3.
    let clustered = json_report(&query(&[
        "--source",
        "features",
        "--features",
        s(&features),
        "--phrases",
        s(&table),
        "--query",
        "Apple",
    ]));
    let count = clustered["count"].as_u64().unwrap() as usize;
    assert!(count <= 398 && count as f64 >= 0.9 * 398.0, "{clustered}");
    assert_eq!(clustered["candidates"], 398);
    assert!(clustered["clustering"]["eps"].as_f64().unwrap() > 0.0);
    assert_eq!(
        clustered["rejected"].as_u64().unwrap() as usize,
        398 - count,
        "{clustered}"
    );

    // A phrase not in the table: the error lists the closest phrases.
    let none = dir.path().join("none");
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--labels",
        s(&sidecar),
        "--features",
        s(&features),
        "--phrases",
        s(&table),
        "--query",
        "appel",
        "--out",
        s(&none),
    ]);
    assert_clean_failure(&out, &["appel", "\"apple\""]);
    assert!(!none.exists());

    // Options of another source are refused rather than ignored.
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--labels",
        s(&sidecar),
        "--source",
        "labels",
        "--phrases",
        s(&table),
        "--query",
        "apple",
        "--out",
        s(&none),
    ]);
    assert_clean_failure(&out, &["--phrases", "labels source"]);
    assert!(!none.exists());
}

/// Pixels of picture `b` tinted toward cyan compared with picture `a` (blue minus red up by
/// more than 10 levels), and pixels tinted away from it (down by more than 10).
fn cyan_shift(a: &Path, b: &Path) -> (usize, usize) {
    let (a, b) = (
        image::open(a).unwrap().to_rgb8(),
        image::open(b).unwrap().to_rgb8(),
    );
    assert_eq!(a.dimensions(), b.dimensions());
    let (mut cyan, mut other) = (0, 0);
    for (p, q) in a.pixels().zip(b.pixels()) {
        let [r0, _, b0] = p.0.map(i32::from);
        let [r1, _, b1] = q.0.map(i32::from);
        let shift = (b1 - r1) - (b0 - r0);
        if shift > 10 {
            cyan += 1;
        }
        if shift < -10 {
            other += 1;
        }
    }
    (cyan, other)
}

#[test]
fn look_alikes_are_dropped_reported_and_shown_with_show_rejected() {
    let (ply, sidecar) = fruit();
    let dir = tempfile::tempdir().unwrap();
    let scene = fruit_scene();
    let ids = &scene.extras.labels.as_ref().unwrap().ids;
    // Label 3 is the apple; so is every 30th Gaussian of labels 5-8, scattered over four
    // other objects on the table.
    let look_alike = |i: usize, id: i32| id >= 5 && i.is_multiple_of(30);
    let features = write_features_as(dir.path(), &scene, |i, id| {
        if look_alike(i, id) { 3 } else { id as usize }
    });
    let look_alikes = (0..ids.len()).filter(|&i| look_alike(i, ids[i])).count();
    assert!(look_alikes > 50, "{look_alikes}");
    let table = dir.path().join("table.json");
    let negative = one_hot(9);
    std::fs::write(
        &table,
        json!({"apple": one_hot(3), "object": negative, "things": negative, "stuff": negative,
               "texture": negative})
        .to_string(),
    )
    .unwrap();
    let top = format!("{}", (398 + look_alikes) as f64 / ids.len() as f64);
    let query = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "query",
            "--scene",
            s(&ply),
            "--labels",
            s(&sidecar),
            "--features",
            s(&features),
            "--phrases",
            s(&table),
            "--query",
            "apple",
            "--top-fraction",
            &top,
            "--json",
            "--out",
            s(out),
        ];
        args.extend_from_slice(extra);
        json_report(&splatraj(&args))
    };
    let plain = dir.path().join("plain");
    let shown = dir.path().join("shown");
    let report = query(&plain, &[]);
    assert_eq!(
        report["candidates"].as_u64().unwrap() as usize,
        398 + look_alikes
    );
    let count = report["count"].as_u64().unwrap() as usize;
    assert!(count <= 398 && count as f64 >= 0.95 * 398.0, "{report}");
    // At least 95% of the look-alikes are dropped, and every dropped candidate is reported.
    let rejected = report["rejected"].as_u64().unwrap() as usize;
    assert!(rejected as f64 >= 0.95 * look_alikes as f64, "{report}");
    assert_eq!(count + rejected, 398 + look_alikes);
    assert_eq!(report["clusters"][0]["kept"], true);
    assert_eq!(report["warnings"], json!([]));
    // Without clustering the look-alikes stay, and the extent is flagged, naming the query.
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--labels",
        s(&sidecar),
        "--features",
        s(&features),
        "--phrases",
        s(&table),
        "--query",
        "apple",
        "--top-fraction",
        &top,
        "--no-cluster",
        "--out",
        s(&dir.path().join("unclustered")),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("warning: query \"apple\"") && err.contains("implausible"),
        "{err}"
    );

    // The picture tints the dropped candidates only with --show-rejected.
    query(&shown, &["--show-rejected"]);
    let (cyan, other) = cyan_shift(&plain.join("query.png"), &shown.join("query.png"));
    magenta_centroid(&shown.join("query.png"), 320, 240);
    assert!(
        cyan > 20 && other == 0,
        "with --show-rejected {cyan} pixels turned toward cyan, {other} away from it"
    );
}

/// The semantic crate's LangSplat fixture (see its README).
fn langsplat_fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("crates/splatraj-semantic/tests/data/langsplat")
        .join(name)
}

#[test]
fn langsplat_route_decodes_latents_and_selects_the_phrases_label() {
    use npyz::WriterBuilder;
    use splatraj_semantic::Matrix;
    let (ply, sidecar) = fruit();
    let dir = tempfile::tempdir().unwrap();
    let scene = fruit_scene();
    let ids = &scene.extras.labels.as_ref().unwrap().ids;
    // Label 3 gets fixture latent 0, every other label one of latents 1-4; the table holds
    // PyTorch's decoding of latent 0 as "apple" and of latents 1-4 as the four negatives, so
    // only label 3 can score above 0.5.
    let latents = Matrix::from_npy(&langsplat_fixture("latents.npy")).unwrap();
    let decoded = Matrix::from_npy(&langsplat_fixture("decoded.npy")).unwrap();
    let mut bytes = Vec::new();
    let mut writer = npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(&[ids.len() as u64, 3])
        .writer(&mut bytes)
        .begin_nd()
        .unwrap();
    for &id in ids {
        let k = if id == 3 { 0 } else { 1 + id as usize % 4 };
        writer.extend(latents.row(k).iter().copied()).unwrap();
    }
    writer.finish().unwrap();
    let latents_path = dir.path().join("latents.npy");
    std::fs::write(&latents_path, bytes).unwrap();
    let table = dir.path().join("table.json");
    std::fs::write(
        &table,
        json!({
            "apple": decoded.row(0), "object": decoded.row(1), "things": decoded.row(2),
            "stuff": decoded.row(3), "texture": decoded.row(4),
        })
        .to_string(),
    )
    .unwrap();

    let checkpoint = langsplat_fixture("best_ckpt.pth");
    let report = json_report(&splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--source",
        "langsplat",
        "--latents",
        s(&latents_path),
        "--checkpoint",
        s(&checkpoint),
        "--phrases",
        s(&table),
        "--query",
        "apple",
        "--top-fraction",
        "0.1",
        "--no-cluster",
        "--json",
        "--out",
        s(dir.path()),
    ]));
    assert_eq!(report["source"], "langsplat");
    assert_eq!(report["count"], 398);
    assert!(report["selected_relevancy"]["min"].as_f64().unwrap() > 0.5);
    let by_label = json_report(&splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--labels",
        s(&sidecar),
        "--query",
        "Category 3",
        "--json",
        "--out",
        s(dir.path()),
    ]));
    assert_eq!(report["centre"], by_label["centre"]);

    // A broken checkpoint: the error names the option, the file and the key; nothing written.
    let none = dir.path().join("none");
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--latents",
        s(&latents_path),
        "--checkpoint",
        s(&langsplat_fixture("bad_missing_bias.pth")),
        "--phrases",
        s(&table),
        "--query",
        "apple",
        "--out",
        s(&none),
    ]);
    assert_clean_failure(
        &out,
        &["--checkpoint", "bad_missing_bias.pth", "decoder.2.bias"],
    );
    assert!(!none.exists());
}

#[test]
fn selection_query_matches_the_editors_file_and_refuses_one_moved() {
    let (ply, _) = fruit();
    let scene = fruit_scene();
    let dir = tempfile::tempdir().unwrap();
    // The Gaussians of a box of the scene, exported as an editor would: their own PLY.
    let (min, max) = ([0.5f32, 0.0, -2.3], [0.75f32, 0.15, -2.0]);
    let keep: Vec<bool> = scene
        .means
        .iter()
        .map(|m| (0..3).all(|k| min[k] <= m[k] && m[k] <= max[k]))
        .collect();
    let cut = scene.subset(&keep);
    let head = dir.path().join("head.ply");
    splatraj_scene::write_inria_ply(&cut, &head).unwrap();
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--selection",
        s(&head),
        "--json",
        "--out",
        s(dir.path()),
    ]);
    let report = json_report(&out);
    assert_eq!(report["source"], "region");
    // Without --query the part is named after the file.
    assert_eq!(report["name"], "head");
    assert_eq!(report["count"].as_u64().unwrap() as usize, cut.len());
    let note = report["notes"][0].as_str().unwrap();
    let all = format!("matched {0} of {0} splats (100.0 %)", cut.len());
    assert!(note.contains(&all), "{note}");

    // The same splats moved by a few centimetres: refused, naming the file and the share.
    let mut moved = cut.clone();
    for m in &mut moved.means {
        m[0] += 0.02;
    }
    let moved_path = dir.path().join("moved.ply");
    splatraj_scene::write_inria_ply(&moved, &moved_path).unwrap();
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--selection",
        s(&moved_path),
        "--query",
        "head",
        "--out",
        s(dir.path()),
    ]);
    assert_clean_failure(&out, &["moved.ply", "not part of this scene", "0.0 %"]);
}

/// An INRIA `cameras.json` of `count` level cameras around `target` at `radius` under world
/// `up` = [0, -1, 0] (a y-down capture), looking at it: `rotation` is R_wc (OpenCV axes) as
/// rows.
fn y_down_cameras_json(target: [f32; 3], radius: f64, count: usize) -> String {
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let cameras: Vec<Value> = (0..count)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / count as f64;
            let t = target.map(f64::from);
            // On a circle in the x-z plane, 0.3 radius above the target (up is −y).
            let c = [
                t[0] + radius * a.cos(),
                t[1] - 0.3 * radius,
                t[2] + radius * a.sin(),
            ];
            let d = [t[0] - c[0], t[1] - c[1], t[2] - c[2]];
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let forward = d.map(|v| v / n);
            // Down is +y without its component along the view.
            let along = forward[1];
            let down = [
                -along * forward[0],
                1.0 - along * forward[1],
                -along * forward[2],
            ];
            let m = (down[0] * down[0] + down[1] * down[1] + down[2] * down[2]).sqrt();
            let down = down.map(|v| v / m);
            let right = cross(down, forward);
            let rows: Vec<[f64; 3]> = (0..3).map(|k| [right[k], down[k], forward[k]]).collect();
            json!({"id": i, "img_name": format!("{i:04}"), "width": 640, "height": 480,
                "position": c, "rotation": rows, "fx": 500.0, "fy": 500.0})
        })
        .collect();
    Value::Array(cameras).to_string()
}

#[test]
fn the_picture_stands_upright_on_the_capture_cameras_beside_the_scene() {
    let (ply, _) = fruit();
    let scene = fruit_scene();
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("fruit.ply");
    std::fs::copy(&ply, &copy).unwrap();
    let b = scene.robust_bounds(0.02).unwrap();
    let size = b.size();
    let diagonal = f64::from((size[0] * size[0] + size[1] * size[1] + size[2] * size[2]).sqrt());
    std::fs::write(
        dir.path().join("cameras.json"),
        y_down_cameras_json(b.center(), diagonal, 16),
    )
    .unwrap();
    let out = splatraj(&[
        "query",
        "--scene",
        s(&copy),
        "--box=0.5,0.0,-2.3,0.75,0.15,-2.0",
        "--query",
        "part",
        "--json",
        "--out",
        s(dir.path()),
    ]);
    let report = json_report(&out);
    assert_eq!(report["camera"]["up_from"], "cameras");
    let up: Vec<f64> = serde_json::from_value(report["camera"]["up"].clone()).unwrap();
    assert!(
        (up[1] + 1.0).abs() < 1e-9 && up[0].abs() < 1e-9 && up[2].abs() < 1e-9,
        "{up:?}"
    );
}
