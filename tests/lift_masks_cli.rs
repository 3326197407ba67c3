//! `splatraj scene lift-masks` end to end: a demo room, its planned views written as an INRIA
//! `cameras.json` and grey label masks of its objects saved as PNGs named after the cameras;
//! the command writes a label sidecar that `splatraj query --labels` then reads.

mod common;

use common::{assert_clean_failure, s, splatraj, stderr, stdout};

use burn::tensor::{DType, Device};
use image::{GrayImage, Luma};
use splatraj::lift::cameras::camera_path;
use splatraj::lift::mask_files::render_label_mask;
use splatraj::lift::progress::silent;
use splatraj::lift::{ViewOptions, plan_views};
use splatraj::render::render::DeviceScene;
use splatraj::scene::demo::DEMO_UP;
use splatraj::scene::{ReadOptions, read_scene};
use splatraj_camera_paths::{ExportOptions, Format};

/// Mask side, pixels.
const SIZE: usize = 128;

#[test]
fn lifted_masks_become_labels_that_query_reads() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ply = d.join("demo.ply");
    let out = splatraj(&["scene", "demo", "--gaussians", "20000", "--out", s(&ply)]);
    assert!(out.status.success(), "{}", stderr(&out));

    // The cameras and the masks a segmenter would give for the demo's objects (ids 3..=10).
    let scene = read_scene(&ply, &ReadOptions::default()).unwrap().scene;
    let truth = scene
        .extras
        .labels
        .as_ref()
        .expect("labelled demo")
        .ids
        .clone();
    let device = Device::default().autodiff();
    let device_scene = DeviceScene::new(&scene, &device, DType::F32);
    let options = ViewOptions {
        count: 12,
        ..ViewOptions::default()
    };
    let plan = plan_views(
        &scene,
        &device_scene,
        DEMO_UP.map(f64::from),
        &options,
        SIZE,
        &silent,
    )
    .unwrap();
    let files = splatraj_camera_paths::export(
        &camera_path(&plan.views),
        Format::Inria,
        &ExportOptions::default(),
    )
    .unwrap();
    let cameras = d.join(files[0].0);
    std::fs::write(&cameras, &files[0].1).unwrap();
    let masks = d.join("masks");
    std::fs::create_dir(&masks).unwrap();
    for (i, view) in plan.views.iter().enumerate() {
        let labels = render_label_mask(&device_scene, &truth, view).unwrap();
        GrayImage::from_fn(SIZE as u32, SIZE as u32, |x, y| {
            let label = labels[y as usize * SIZE + x as usize];
            Luma([label.filter(|l| (3..=10).contains(l)).unwrap_or(0) as u8])
        })
        .save(masks.join(format!("frame_{i:04}.png")))
        .unwrap();
    }

    let sidecar = d.join("labels.json");
    let out = splatraj(&[
        "scene",
        "lift-masks",
        "--scene",
        s(&ply),
        "--cameras",
        s(&cameras),
        "--masks",
        s(&masks),
        "--out",
        s(&sidecar),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let summary = stdout(&out);
    println!("{summary}");
    assert!(
        summary.contains(&format!(
            "cameras:    {0} of {0} with a mask",
            plan.views.len()
        )),
        "{summary}"
    );
    assert!(summary.contains("labels:     8 in the masks"), "{summary}");
    assert!(summary.contains("unseen:"), "{summary}");

    // Every object got Gaussians, mostly its own.
    let lifted = read_scene(
        &ply,
        &ReadOptions {
            labels: Some(sidecar.clone()),
            ..ReadOptions::default()
        },
    )
    .unwrap()
    .scene;
    let ids = &lifted.extras.labels.as_ref().unwrap().ids;
    for object in 3..=10 {
        let ours = (0..ids.len()).filter(|&i| ids[i] == object).count();
        let right = (0..ids.len())
            .filter(|&i| ids[i] == object && truth[i] == object)
            .count();
        assert!(
            ours > 0 && right * 10 >= ours * 8,
            "object {object}: {right} of {ours}"
        );
    }

    let out = splatraj(&[
        "query",
        "--scene",
        s(&ply),
        "--labels",
        s(&sidecar),
        "--query",
        "4",
        "--out",
        s(d),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(d.join("query.png").is_file());

    // A folder in the way is not replaced.
    let out = splatraj(&[
        "scene",
        "lift-masks",
        "--scene",
        s(&ply),
        "--cameras",
        s(&cameras),
        "--masks",
        s(&masks),
        "--out",
        s(&masks),
    ]);
    assert_clean_failure(&out, &[s(&masks), "not a regular file"]);
}
