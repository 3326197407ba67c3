//! Every config in `configs/` is parsed and checked; bad keys and values are named; `--set`
//! and `extends` do what the docs say.

use std::path::{Path, PathBuf};

use splatraj::config::{Ablation, Config, apply_override};
use splatraj::traj::trajectory::TrajectoryModel;

fn configs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("configs")
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

const MINIMAL: &str = r#"
name = "t"
[scene]
demo = { gaussians = 2000 }
[[queries]]
text = "red mug"
"#;

#[test]
fn every_shipped_config_parses_and_validates() {
    let mut seen = 0;
    for entry in std::fs::read_dir(configs_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let config =
                Config::load(&path, &[]).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
            assert!(!config.queries.is_empty());
            seen += 1;
        }
    }
    assert!(
        seen >= 4,
        "demo, its two model variants and the pose config"
    );
}

/// The first-try configs name only the scene, the targets and the queries, and get the
/// defaults docs/first-try.md lists.
#[test]
fn first_try_configs_are_minimal_and_get_the_documented_defaults() {
    let dir = configs_dir().join("first-try");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let table: toml::Table = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        for key in table.keys() {
            assert!(
                ["name", "scene", "targets", "queries"].contains(&key.as_str()),
                "{}: `{key}` is not a first-try key",
                path.display()
            );
        }
        let config =
            Config::load(&path, &[]).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
        let costs = &config.costs;
        assert!(costs.tce.is_some() && costs.tre.is_some() && costs.prior.is_some());
        assert_eq!(
            costs.upright.as_ref().unwrap().mode,
            splatraj::traj::costs::UprightMode::Roll
        );
        assert!(costs.clearance.as_ref().unwrap().margin.is_auto());
        assert!(costs.motion.as_ref().unwrap().max_speed.unwrap().is_auto());
        // Under the verdict's pacing limits of 45°/s (docs/conventions.md, "Pacing").
        assert_eq!(costs.motion.as_ref().unwrap().max_angular_speed, Some(36.0));
        assert_eq!(costs.motion.as_ref().unwrap().max_orbit_speed, Some(36.0));
        assert!(costs.visibility.is_some());
        match &config.trajectory {
            splatraj::traj::trajectory::TrajectoryModel::Rbf(rbf) => {
                assert_eq!(rbf.centres_per_window, 4);
                assert_eq!(
                    rbf.normalisation,
                    splatraj::traj::trajectory::RbfNormalisation::PartitionOfUnity
                );
            }
            other => panic!("{}: {other:?}", path.display()),
        }
        assert_eq!(
            config.start.kind,
            splatraj::experiment::config::StartKind::Search
        );
        let output = &config.output;
        assert_eq!((output.width, output.height, output.fps), (1280, 720, 30.0));
        assert_eq!(
            output.frame_count(config.queries.len()),
            90 * config.queries.len()
        );
        assert_eq!(
            output.mask_overlay,
            splatraj::experiment::config::MaskOverlay::None
        );
        seen += 1;
    }
    assert_eq!(seen, 4, "guitar, biker, donut, fruit_drops");
}

#[test]
fn model_variants_differ_only_in_their_model() {
    let base = Config::load(&configs_dir().join("demo.toml"), &[]).unwrap();
    assert_eq!(base.queries.len(), 3, "the demo asks for three objects");
    for (file, kind) in [
        ("demo-waypoint.toml", "waypoint"),
        ("demo-polynomial.toml", "polynomial"),
    ] {
        let variant = Config::load(&configs_dir().join(file), &[]).unwrap();
        assert_eq!(variant.trajectory.name(), kind);
        assert_eq!(variant.queries, base.queries);
        assert_eq!(variant.optimiser, base.optimiser);
        assert_eq!(variant.costs, base.costs);
    }
    assert!(matches!(base.trajectory, TrajectoryModel::Rbf(_)));
}

#[test]
fn unknown_keys_are_named() {
    let dir = tempfile::tempdir().unwrap();
    for (text, key) in [
        (format!("{MINIMAL}\nbogus = 1\n"), "bogus"),
        (
            format!("{MINIMAL}\n[optimiser]\niteratons = 5\n"),
            "iteratons",
        ),
        (format!("{MINIMAL}\n[costs.tce]\nwieght = 2\n"), "wieght"),
        (
            format!("{MINIMAL}\n[trajectory]\nkind = \"rbf\"\nsegments = 3\n"),
            "segments",
        ),
        (format!("{MINIMAL}\n[output]\nframe = 3\n"), "frame"),
    ] {
        let path = write(dir.path(), "c.toml", &text);
        let err = format!("{:#}", Config::load(&path, &[]).unwrap_err());
        assert!(err.contains(key), "error should name `{key}`: {err}");
        assert!(err.contains("c.toml"), "error should name the file: {err}");
    }
}

#[test]
fn out_of_range_values_are_named() {
    let dir = tempfile::tempdir().unwrap();
    for (set, key) in [
        ("optimiser.samples_per_window=0", "samples_per_window"),
        ("optimiser.learning_rate=-1", "learning_rate"),
        ("camera.width=0", "camera.width"),
        ("camera.target_ratio=1.5", "camera.target_ratio"),
        ("queries.0.target_ratio=0", "queries.0.target_ratio"),
        ("costs.prior.gamma=2", "costs.prior.gamma"),
        ("start.restarts=0", "start.restarts"),
        ("start.spread=3", "start.spread"),
        ("sgld.burn_in=1000", "burn_in"),
        ("pose.query=5", "pose.query"),
        ("output.ldj_samples=2", "output.ldj_samples"),
        ("name=\"a b\"", "name"),
    ] {
        let path = write(dir.path(), "c.toml", MINIMAL);
        let err = format!("{:#}", Config::load(&path, &[set.to_string()]).unwrap_err());
        assert!(
            err.contains(key),
            "--set {set}: error should name `{key}`: {err}"
        );
    }
}

#[test]
fn overrides_reach_nested_keys_and_list_entries() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "c.toml", MINIMAL);
    let config = Config::load(
        &path,
        &[
            "optimiser.iterations=7".into(),
            "queries.0.text=lamp".into(),
            "trajectory.kind=waypoint".into(),
            "pose.ablation=prior-tce".into(),
            "output.runs_dir=elsewhere".into(),
        ],
    )
    .unwrap();
    assert_eq!(config.optimiser.iterations, 7);
    assert_eq!(config.queries[0].text, "lamp");
    assert_eq!(config.trajectory.name(), "waypoint");
    assert_eq!(config.pose.ablation, Ablation::PriorTce);
    assert_eq!(config.output.runs_dir, PathBuf::from("elsewhere"));

    let mut table: toml::Table = toml::from_str(MINIMAL).unwrap();
    let err = apply_override(&mut table, "queries.3.text=x").unwrap_err();
    assert!(format!("{err:#}").contains("out of range"));
    assert!(apply_override(&mut table, "no-equals-sign").is_err());
}

#[test]
fn ablations_pick_their_costs() {
    let full = splatraj::traj::costs::CostsConfig::default();
    let names = |a: Ablation| a.apply(&full).build().unwrap().names();
    assert_eq!(names(Ablation::Prior), ["upright", "prior"]);
    assert_eq!(names(Ablation::PriorTce), ["tce", "upright", "prior"]);
    assert_eq!(names(Ablation::PriorTre), ["tre", "upright", "prior"]);
    assert_eq!(
        names(Ablation::PriorTceTre),
        ["tce", "tre", "upright", "prior"]
    );
    assert_eq!(names(Ablation::Full), ["tce", "tre", "upright", "prior"]);
}

#[test]
fn extends_merges_tables_and_detects_cycles() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "base.toml",
        &format!("{MINIMAL}\n[optimiser]\niterations = 9\nlearning_rate = 0.5\n"),
    );
    let child = write(
        dir.path(),
        "child.toml",
        "extends = \"base.toml\"\nname = \"child\"\n[optimiser]\niterations = 3\n",
    );
    let config = Config::load(&child, &[]).unwrap();
    assert_eq!(config.name, "child");
    assert_eq!(config.optimiser.iterations, 3);
    assert_eq!(config.optimiser.learning_rate, 0.5, "kept from the base");
    let a = write(dir.path(), "a.toml", "extends = \"b.toml\"\n");
    write(dir.path(), "b.toml", "extends = \"a.toml\"\n");
    let err = format!("{:#}", Config::load(&a, &[]).unwrap_err());
    assert!(err.contains("extends"), "{err}");
}
