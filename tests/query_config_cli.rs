//! `splatraj query` reaches every target source: `--config RUN.toml` builds the scene and the
//! `[targets]` source (registered ones included) as `run` does, and `--source custom.<name>`
//! with `--source-key` does the same from the command line. Checked on the fixtures of the
//! registered language fields (crates/splatraj-semantic/tests/data, made by the kept scripts
//! in scripts/): Gaussian Grouping's classified instances against PyTorch's classes, and a
//! LEGaussians free-text query explained with LEGaussians' own relevancies. Bad input fails
//! naming the file, key or source, and writes nothing.

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{TINY_CONFIG, assert_clean_failure, s, splatraj, stderr, stdout};
use serde_json::Value;

fn data(source: &str, name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("crates/splatraj-semantic/tests/data")
        .join(source)
        .join(name)
}

fn tower() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("crates/splatraj-semantic/tests/fixtures/clip/gelu/open_clip_model.safetensors")
}

fn npy<T: npyz::Deserialize>(path: &Path) -> Vec<T> {
    npyz::NpyFile::new(&std::fs::read(path).unwrap()[..])
        .unwrap()
        .into_vec::<T>()
        .unwrap()
}

fn json_report(out: &Output) -> Value {
    assert!(out.status.success(), "{}", stderr(out));
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("stdout is not one JSON object ({e}): {}", stdout(out)))
}

/// `query ARGS` with a small picture written into `out`.
fn query(out: &Path, args: &[&str]) -> Output {
    let mut all = vec!["query", "--out", s(out), "--width", "64", "--height", "48"];
    all.extend(args);
    splatraj(&all)
}

/// `query --config CONFIG --query TEXT` (picture into `dir/out`) plus `extra`.
fn query_config(dir: &Path, config: &Path, text: &str, extra: &[&str]) -> Output {
    let mut args = vec!["--config", s(config), "--query", text];
    args.extend(extra);
    query(&dir.join("out"), &args)
}

/// A Gaussian Grouping run config beside copies of the fixture's PLY and classifier, its
/// paths relative to the config's folder (as `run` resolves them).
fn gaussian_grouping_config(dir: &Path) -> PathBuf {
    for name in ["point_cloud.ply", "classifier.pth"] {
        std::fs::copy(data("gaussian_grouping", name), dir.join(name)).unwrap();
    }
    let config = dir.join("grouping.toml");
    std::fs::write(
        &config,
        r#"
name = "grouping"
[scene]
path = "point_cloud.ply"
[targets]
source = "custom.gaussian_grouping"
[targets.custom.gaussian_grouping]
classifier = "classifier.pth"
label_names = { "7" = "teapot" }
[[queries]]
text = "teapot"
"#,
    )
    .unwrap();
    config
}

/// The Gaussians PyTorch put in class `id` with probability at least `min`.
fn pytorch_members(id: i64, min: f32) -> Vec<usize> {
    let ids = npy::<i64>(&data("gaussian_grouping", "expected_ids.npy"));
    let prob = npy::<f32>(&data("gaussian_grouping", "expected_prob.npy"));
    (0..ids.len())
        .filter(|&i| ids[i] == id && prob[i] >= min)
        .collect()
}

#[test]
fn config_query_selects_a_gaussian_grouping_instance() {
    let dir = tempfile::tempdir().unwrap();
    let config = gaussian_grouping_config(dir.path());
    // By the name the config gives class 7: its Gaussians as PyTorch classifies them, the blob
    // the fixture planted around (2, 0, 0).
    let report = json_report(&query_config(dir.path(), &config, "Teapot", &["--json"]));
    let members = pytorch_members(7, 0.3);
    assert!((40..=50).contains(&members.len()), "{}", members.len());
    assert_eq!(report["source"], "custom.gaussian_grouping");
    assert_eq!(report["count"].as_u64().unwrap() as usize, members.len());
    assert_eq!(report["gaussians"], 220);
    let centre: Vec<f64> = (0..3)
        .map(|i| report["centre"][i].as_f64().unwrap())
        .collect();
    let distance = ((centre[0] - 2.0).powi(2) + centre[1].powi(2) + centre[2].powi(2)).sqrt();
    assert!(distance < 0.3, "centre {centre:?}");
    assert!(dir.path().join("out/query.png").exists());

    // --set edits the config before it is built: a stricter min_probability leaves PyTorch's
    // unsure members of class 7 out.
    let strict = json_report(&query_config(
        dir.path(),
        &config,
        "7",
        &[
            "--json",
            "--set",
            "targets.custom.gaussian_grouping.min_probability=0.5",
        ],
    ));
    let sure = pytorch_members(7, 0.5);
    assert!(
        sure.len() < members.len(),
        "{} {}",
        sure.len(),
        members.len()
    );
    assert_eq!(strict["count"].as_u64().unwrap() as usize, sure.len());

    // The options override the config's keys, and --set overrides both (low to high: the
    // file, the options, --set): --source-key sets the key the --set above set.
    let stricter = ["--source", "custom.gaussian_grouping"];
    let by_option = json_report(&query_config(
        dir.path(),
        &config,
        "7",
        &[
            "--json",
            stricter[0],
            stricter[1],
            "--source-key",
            "min_probability=0.5",
        ],
    ));
    assert_eq!(by_option["count"].as_u64().unwrap() as usize, sure.len());
    let set_wins = json_report(&query_config(
        dir.path(),
        &config,
        "7",
        &[
            "--json",
            stricter[0],
            stricter[1],
            "--source-key",
            "min_probability=0.5",
            "--set",
            "targets.custom.gaussian_grouping.min_probability=0.3",
        ],
    ));
    assert_eq!(set_wins["count"].as_u64().unwrap() as usize, members.len());

    // The text report labels the selected-only spread apart from the all-Gaussians one.
    let out = query_config(dir.path(), &config, "teapot", &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    println!("{text}");
    assert!(
        text.contains("(custom.gaussian_grouping source) matched \"teapot\""),
        "{text}"
    );
    assert!(
        text.contains(&format!(
            "relevancy of the {} selected Gaussians: min 1.0000",
            members.len()
        )),
        "{text}"
    );
}

/// Gaussians of the tiny config's demo room (3000, seed 7) labelled `name`.
fn demo_label_count(name: &str) -> usize {
    let scene = splatraj_scene::demo::demo_scene(&splatraj_scene::demo::DemoConfig {
        seed: 7,
        gaussians: 3000,
    })
    .unwrap();
    let labels = scene.extras.labels.as_ref().unwrap();
    let id = labels
        .names
        .iter()
        .find(|(_, label)| label.as_str() == name)
        .map(|(&id, _)| id)
        .unwrap();
    labels.ids.iter().filter(|&&i| i == id).count()
}

#[test]
fn config_query_builds_the_demo_room_as_runs_do() {
    // A run config of the demo room (labels): the scene is generated, its up is the room's.
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("tiny.toml");
    std::fs::write(&config, TINY_CONFIG).unwrap();
    let report = json_report(&query_config(dir.path(), &config, "blue box", &["--json"]));
    let expected = demo_label_count("blue box");
    assert!(expected > 0);
    assert_eq!(report["count"].as_u64().unwrap() as usize, expected);
    assert_eq!(report["source"], "labels");
    let up: Vec<f64> = (0..3)
        .map(|i| report["camera"]["up"][i].as_f64().unwrap())
        .collect();
    let demo_up = splatraj_scene::demo::DEMO_UP;
    for i in 0..3 {
        assert!((up[i] - f64::from(demo_up[i])).abs() < 1e-9, "{up:?}");
    }
}

#[test]
fn config_without_query_checks_every_query_of_the_config() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("tiny.toml");
    std::fs::write(&config, TINY_CONFIG).unwrap();
    let out = dir.path().join("out");
    let all = query(&out, &["--config", s(&config), "--json"]);
    let entries = json_report(&all);
    let entries = entries
        .as_array()
        .expect("one JSON array, an entry per query");
    assert_eq!(entries.len(), 2, "the config's two [[queries]]");
    for (i, (entry, name)) in entries.iter().zip(["red mug", "blue box"]).enumerate() {
        assert_eq!(entry["key"], format!("queries.{i}.text"));
        let report = &entry["report"];
        assert_eq!(report["query"], name);
        assert_eq!(
            report["count"].as_u64().unwrap() as usize,
            demo_label_count(name)
        );
        assert!(out.join(format!("query-{}.png", i + 1)).is_file());
    }
    assert!(!out.join("query.png").exists());

    // As text: a header per query, then its report.
    let text = query(&out, &["--config", s(&config)]);
    assert!(text.status.success(), "{}", stderr(&text));
    let printed = stdout(&text);
    assert!(printed.contains("== queries.0.text: red mug"), "{printed}");
    assert!(printed.contains("== queries.1.text: blue box"), "{printed}");

    // A query that finds nothing does not stop the others; the run fails naming its key.
    let with_unknown = dir.path().join("unknown.toml");
    std::fs::write(
        &with_unknown,
        TINY_CONFIG.replace(
            "[camera]",
            "[[queries]]\ntext = \"purple unicorn\"\n[[queries]]\ntext = \"plant\"\n[camera]",
        ),
    )
    .unwrap();
    let out = dir.path().join("out-unknown");
    let partial = query(&out, &["--config", s(&with_unknown), "--json"]);
    assert!(!partial.status.success());
    let err = stderr(&partial);
    let last = err.trim_end().lines().last().unwrap_or_default();
    assert!(
        last.starts_with("error: ") && !err.contains("panicked"),
        "{err}"
    );
    for mention in ["unknown.toml", "queries.2.text", "purple unicorn"] {
        assert!(
            last.contains(mention),
            "{last:?} does not mention {mention:?}"
        );
    }
    let entries: Value = serde_json::from_slice(&partial.stdout).expect("the array still prints");
    let entries = entries.as_array().unwrap();
    assert_eq!(entries.len(), 4);
    assert!(
        entries[2]["error"]
            .as_str()
            .unwrap()
            .contains("purple unicorn")
    );
    assert_eq!(entries[3]["report"]["query"], "plant");
    assert!(out.join("query-4.png").is_file() && !out.join("query-3.png").exists());

    // Without --config, --query is still required (clap's usage error).
    let missing = query(&out, &["--scene", s(&config)]);
    assert!(!missing.status.success());
    assert!(stderr(&missing).contains("--query"), "{}", stderr(&missing));
}

/// LEGaussians' own relevancy (scale 100, argmax codes, open_clip's embeddings) of
/// "green ball", from the fixture's reference file.
fn legaussians_green_ball() -> Vec<f32> {
    let all = npy::<f32>(&data("legaussians", "expected_relevancy_argmax.npy"));
    let n = all.len() / 3;
    all[n..2 * n].to_vec()
}

#[test]
fn free_text_through_a_registered_language_field_is_explained() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("legaussians.toml");
    std::fs::write(
        &config,
        format!(
            r#"
name = "lem"
[scene]
path = {ply:?}
[targets]
source = "custom.legaussians"
[targets.custom.legaussians]
index_decoder = {decoder:?}
codebook = {codebook:?}
text_encoder = {tower:?}
[targets.selection]
top_fraction = 0.3
[[queries]]
text = "green ball"
"#,
            ply = s(&data("legaussians", "point_cloud.ply")),
            decoder = s(&data("legaussians", "index_decoder_chkpnt.pth")),
            codebook = s(&data("legaussians", "codebook.pt")),
            tower = s(&tower()),
        ),
    )
    .unwrap();
    let reference = legaussians_green_ball();
    let max = reference.iter().copied().fold(0.0f32, f32::max);
    let above = reference.iter().filter(|&&r| r > 0.5).count();
    assert_eq!(above, 40, "the fixture plants a blob of 40");

    let by_config = json_report(&query_config(
        dir.path(),
        &config,
        "green ball",
        &["--json"],
    ));
    // The same source from the command line: --source-key for its own keys, --text-encoder
    // and --top-fraction as for the built-in sources.
    let by_options = json_report(&query(
        &dir.path().join("out2"),
        &[
            "--scene",
            s(&data("legaussians", "point_cloud.ply")),
            "--source",
            "custom.legaussians",
            "--source-key",
            &format!(
                "index_decoder={:?}",
                s(&data("legaussians", "index_decoder_chkpnt.pth"))
            ),
            "--source-key",
            &format!("codebook={}", s(&data("legaussians", "codebook.pt"))),
            "--text-encoder",
            s(&tower()),
            "--top-fraction",
            "0.3",
            "--query",
            "green ball",
            "--json",
        ],
    ));
    for (route, report) in [("--config", &by_config), ("--source", &by_options)] {
        let x = &report["explanation"];
        let printed = x["quantiles"]["max"].as_f64().unwrap() as f32;
        // Scale 100 turns the encoder's 1e-7 from open_clip into about 1e-5 here.
        assert!(
            (printed - max).abs() < 1e-4,
            "{route}: max {printed} vs {max}"
        );
        assert_eq!(
            x["above_floor"].as_u64().unwrap() as usize,
            above,
            "{route}"
        );
        assert_eq!(
            report["candidates"].as_u64().unwrap() as usize,
            above,
            "{route}"
        );
        assert_eq!(report["source"], "custom.legaussians", "{route}");
        let top = &x["top"][0];
        assert!(
            (top["centre"][0].as_f64().unwrap() - 2.0).abs() < 0.3,
            "{route}: {top}"
        );
        let count = report["count"].as_u64().unwrap();
        assert!((30..=40).contains(&count), "{route}: {count}");
    }
    assert_eq!(by_config["count"], by_options["count"]);

    // As text: the explanation and the selected-only spread, each labelled.
    let out = query_config(dir.path(), &config, "green ball", &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    println!("{text}");
    for words in [
        "relevancy of \"green ball\" over all Gaussians: min",
        "thresholds: floor 0.5000 (40 Gaussians above), top 30% percentile",
        "most relevant",
        "selected Gaussians: min",
    ] {
        assert!(text.contains(words), "{words:?} not in\n{text}");
    }
}

#[test]
fn bad_configs_and_sources_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("out/query.png");
    let config = gaussian_grouping_config(dir.path());

    // A config that is not there.
    let missing = dir.path().join("nowhere.toml");
    let out = query_config(dir.path(), &missing, "teapot", &[]);
    assert_clean_failure(&out, &["nowhere.toml"]);

    // A source nobody registered, in a config and on the command line: the error names it
    // and lists the registered ones.
    let out = query_config(
        dir.path(),
        &config,
        "teapot",
        &["--set", "targets.source=custom.nope"],
    );
    assert_clean_failure(&out, &["custom.nope", "gaussian_grouping, legaussians"]);
    let ply = dir.path().join("point_cloud.ply");
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--source",
        "custom.nope",
        "--query",
        "7",
        "--out",
        s(&dir.path().join("out")),
    ]);
    assert_clean_failure(&out, &["custom.nope", "gaussian_grouping, legaussians"]);
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--source",
        "bogus",
        "--query",
        "7",
    ]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("unknown source \"bogus\""),
        "{}",
        stderr(&out)
    );

    // A registered source's file that is not there: the key and the file.
    let out = query_config(
        dir.path(),
        &config,
        "teapot",
        &[
            "--set",
            "targets.custom.gaussian_grouping.classifier=gone.pth",
        ],
    );
    assert_clean_failure(
        &out,
        &["targets.custom.gaussian_grouping", "classifier", "gone.pth"],
    );
    // Its required key left out on the command line, and a --source-key for a built-in
    // source.
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--source",
        "custom.gaussian_grouping",
        "--query",
        "7",
    ]);
    assert_clean_failure(&out, &["--source custom.gaussian_grouping", "classifier"]);
    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--source",
        "region",
        "--sphere",
        "0,0,0,1",
        "--source-key",
        "classifier=classifier.pth",
        "--query",
        "ball",
    ]);
    assert_clean_failure(&out, &["--source-key", "region"]);

    // An option overrides the config's key, so an option of another source is a key the
    // config's source does not take: refused naming the key and both sources.
    let out = query_config(dir.path(), &config, "teapot", &["--phrases", "table.json"]);
    assert_clean_failure(
        &out,
        &[
            "targets.phrases",
            "features and langsplat",
            "custom.gaussian_grouping source",
        ],
    );
    assert!(!png.exists(), "a failed query wrote {}", png.display());
}
