//! A part given as a file of selected splats (`regions = { head = { selection = "head.ply" } }`):
//! a selection cut from a real scene and written with the project's writers matches exactly
//! the Gaussians it was cut from; one moved, from another capture, or empty is refused naming
//! the file.

mod common;

use std::path::{Path, PathBuf};

use splatraj_scene::{ReadOptions, Scene, SceneFormat, read_scene, write_scene};
use splatraj_semantic::{
    SelectionFile, SelectionOptions, TargetsConfig, find_target, match_selection,
};

#[path = "../../splatraj-scene/tests/common/shared_data.rs"]
mod shared_data;
use shared_data::shared_data;

fn read(path: &Path) -> Scene {
    read_scene(path, &ReadOptions::default()).unwrap().scene
}

/// The indices of `scene` whose centre lies in the ball around `centre_of` (a Gaussian's
/// index) holding about `share` of the scene.
fn ball_around(scene: &Scene, centre_of: usize, share: f64) -> Vec<usize> {
    let c = scene.means[centre_of];
    let mut d: Vec<(f32, usize)> = scene
        .means
        .iter()
        .enumerate()
        .map(|(i, m)| ((0..3).map(|k| (m[k] - c[k]).powi(2)).sum::<f32>(), i))
        .collect();
    d.sort_by(|a, b| a.0.total_cmp(&b.0));
    let count = ((scene.len() as f64 * share) as usize).max(1);
    let mut picked: Vec<usize> = d[..count].iter().map(|(_, i)| *i).collect();
    picked.sort_unstable();
    picked
}

fn cut(scene: &Scene, indices: &[usize]) -> Scene {
    let mut keep = vec![false; scene.len()];
    for &i in indices {
        keep[i] = true;
    }
    scene.subset(&keep)
}

fn write(scene: &Scene, dir: &Path, name: &str, format: SceneFormat) -> PathBuf {
    let path = dir.join(name);
    write_scene(scene, &path, format).unwrap();
    path
}

/// Largest distance from a written splat to the Gaussian it was cut from, over the scene's
/// spacing as the matcher measures it (printed: the module docs quote it).
fn displacement(scene: &Scene, indices: &[usize], selection: &Scene, spacing: f32) -> f32 {
    // Writers may reorder (compressed PLY sorts by chunk): compare each written splat with
    // its nearest original among the cut ones.
    selection
        .means
        .iter()
        .map(|p| {
            indices
                .iter()
                .map(|&i| {
                    let m = scene.means[i];
                    (0..3).map(|k| (m[k] - p[k]).powi(2)).sum::<f32>().sqrt()
                })
                .fold(f32::INFINITY, f32::min)
        })
        .fold(0.0, f32::max)
        / spacing
}

#[test]
fn a_selection_cut_from_a_real_scene_matches_exactly_its_gaussians_in_every_written_format() {
    let mut scenes = vec![(
        "fruit_drops",
        common::data_dir().join("fruit_drops_minimal.ply"),
    )];
    for name in [
        "biker.compressed.ply",
        "guitar.compressed.ply",
        "donut_fused.ply",
    ] {
        if let Some(path) = shared_data(name) {
            scenes.push((name, path));
        }
    }
    let dir = tempfile::tempdir().unwrap();
    for (name, path) in scenes {
        let scene = read(&path);
        let indices = ball_around(&scene, scene.len() / 3, 0.03);
        let part = cut(&scene, &indices);
        for format in [
            SceneFormat::InriaPly,
            SceneFormat::CompressedPly,
            SceneFormat::Spz,
        ] {
            let file = write(
                &part,
                dir.path(),
                &format!("{name}-part{}", format.extension()),
                format,
            );
            let selection = SelectionFile::read(&file).unwrap();
            let matched = match_selection(&scene, &selection)
                .unwrap_or_else(|e| panic!("{name} as {format:?}: {e}"));
            let moved = displacement(&scene, &indices, &selection.splats, matched.spacing);
            eprintln!(
                "{name} as {format:?}: {} of {} matched, centres moved by at most {moved:.3} \
                 spacings (spacing {:.3e})",
                matched.indices.len(),
                indices.len(),
                matched.spacing
            );
            assert_eq!(matched.indices, indices, "{name} as {format:?}");
            assert!(
                matched.describe(&file).contains("(100.0 %)"),
                "{}",
                matched.describe(&file)
            );
        }
    }
}

#[test]
fn a_moved_selection_is_refused_naming_the_file_the_share_and_the_distance() {
    let path = common::data_dir().join("fruit_drops_minimal.ply");
    let scene = read(&path);
    let indices = ball_around(&scene, 100, 0.05);
    let mut part = cut(&scene, &indices);
    // Moved by 2 % of the scene's size along x, as an editor's transform would move it.
    let size = scene.bounds().unwrap().size();
    for m in &mut part.means {
        m[0] += 0.02 * size[0];
    }
    let dir = tempfile::tempdir().unwrap();
    let file = write(&part, dir.path(), "moved.ply", SceneFormat::InriaPly);
    let error = match_selection(&scene, &SelectionFile::read(&file).unwrap())
        .unwrap_err()
        .to_string();
    eprintln!("{error}");
    assert!(error.contains("moved.ply"), "names the file: {error}");
    assert!(error.contains("not part of this scene"), "{error}");
    assert!(error.contains("median distance"), "says how far: {error}");
    assert!(error.contains(" %"), "says the share: {error}");
}

#[test]
fn a_selection_from_another_capture_is_refused() {
    let (Some(guitar), Some(biker)) = (
        shared_data("guitar.compressed.ply"),
        shared_data("biker.compressed.ply"),
    ) else {
        return;
    };
    let guitar = read(&guitar);
    let biker = read(&biker);
    // A part of the guitar, matched against the biker (both PlayCanvas captures, y down).
    let part = cut(&guitar, &ball_around(&guitar, guitar.len() / 2, 0.05));
    let dir = tempfile::tempdir().unwrap();
    let file = write(&part, dir.path(), "guitar_part.ply", SceneFormat::InriaPly);
    let error = match_selection(&biker, &SelectionFile::read(&file).unwrap())
        .unwrap_err()
        .to_string();
    eprintln!("{error}");
    assert!(error.contains("guitar_part.ply") && error.contains("not part of this scene"));
}

#[test]
fn an_empty_selection_is_refused_naming_the_file() {
    let scene = read(&common::data_dir().join("fruit_drops_minimal.ply"));
    let empty = cut(&scene, &[]);
    let dir = tempfile::tempdir().unwrap();
    let file = write(&empty, dir.path(), "nothing.ply", SceneFormat::InriaPly);
    let error = SelectionFile::read(&file).unwrap_err().to_string();
    assert!(
        error.contains("nothing.ply") && error.contains("empty"),
        "{error}"
    );
}

#[test]
fn a_few_splats_left_out_are_noted_not_refused() {
    let scene = read(&common::data_dir().join("fruit_drops_minimal.ply"));
    let indices = ball_around(&scene, 2000, 0.25);
    let mut part = cut(&scene, &indices);
    // One splat in 400 moved far away: 99.75 % still match.
    for i in (0..part.len()).step_by(400) {
        part.means[i][2] += 10.0;
    }
    let dir = tempfile::tempdir().unwrap();
    let file = write(&part, dir.path(), "mostly.ply", SceneFormat::InriaPly);
    let matched = match_selection(&scene, &SelectionFile::read(&file).unwrap()).unwrap();
    let left = part.len().div_ceil(400);
    assert_eq!(matched.indices.len(), indices.len() - left);
    assert!(
        matched
            .describe(&file)
            .contains(&format!("{left} left out")),
        "{}",
        matched.describe(&file)
    );
}

#[test]
fn a_config_region_names_a_selection_file_relative_to_the_config() {
    let scene = read(&common::data_dir().join("fruit_drops_minimal.ply"));
    let indices = ball_around(&scene, 300, 0.04);
    let dir = tempfile::tempdir().unwrap();
    write(
        &cut(&scene, &indices),
        dir.path(),
        "part.ply",
        SceneFormat::InriaPly,
    );
    let [x, y, z] = scene.means[1000];
    let targets: TargetsConfig = toml::from_str(&format!(
        "source = \"region\"\nregions = {{ part = {{ selection = \"part.ply\" }}, ball = {{ \
         sphere = [{x}, {y}, {z}, 0.05] }} }}\n",
    ))
    .unwrap();
    let source = targets
        .build(dir.path(), &burn::tensor::Device::flex())
        .unwrap();
    let options = SelectionOptions::default();
    let target = find_target(source.as_ref(), &scene, "Part", &options).unwrap();
    assert_eq!(target.indices(), indices);
    assert_eq!(target.name, "part");
    assert!(target.notes[0].contains("part.ply"), "{:?}", target.notes);
    // The ball still works beside it.
    let ball = find_target(source.as_ref(), &scene, "ball", &options).unwrap();
    assert!(ball.notes.is_empty());

    // A missing file is an error naming the key and the file.
    let missing: TargetsConfig =
        toml::from_str("source = \"region\"\nregions = { head = { selection = \"head.ply\" } }\n")
            .unwrap();
    let error = missing
        .build(dir.path(), &burn::tensor::Device::flex())
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("regions.head.selection") && error.contains("head.ply"),
        "{error}"
    );
}
