//! The views page (`scene views`): its embedded cameras and depths unproject a pixel to the
//! point a closed form gives, and the page is written whole or refused with the file named.

use std::f64::consts::PI;

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use burn::tensor::{DType, Device};
use splatraj_experiment::picking::views_page::{
    PageText, ViewsPageOptions, ViewsPageRequest, views_page, write_views_page,
};
use splatraj_lift::{LiftStage, View};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::DeviceScene;
use splatraj_report::views_page::DATA_ELEMENT_ID;
use splatraj_scene::demo::{DemoConfig, demo_scene};
use splatraj_scene::{ReadOptions, Scene, write_inria_ply};

/// Height of the camera above the plane z = 0.
const HEIGHT: f64 = 4.0;

fn silent(_: LiftStage, _: usize, _: usize) {}

/// Two flat, opaque discs facing +z, both of std 0.4: one at the origin (z = 0), one at
/// (−3.5, 0, −3), far enough apart in the picture that neither adds to the other's middle (with
/// std 0.6 the near one still had α > 1/255 there, and the depth came out 0.2 % short of 7:
/// depth is composited like colour).
fn two_discs() -> Scene {
    Scene {
        means: vec![[0.0, 0.0, 0.0], [-3.5, 0.0, -3.0]],
        scales: vec![[0.4, 0.4, 1e-4]; 2],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; 2],
        opacities: vec![0.999; 2],
        sh_degree: 0,
        sh: vec![1.0, 0.5, 0.2, 0.2, 0.5, 1.0],
        ..Scene::default()
    }
}

/// The page's data block as JSON.
fn page_data(html: &str) -> serde_json::Value {
    let open = format!("id=\"{DATA_ELEMENT_ID}\">");
    let start = html.find(&open).expect("data block") + open.len();
    let end = start + html[start..].find("</script>").expect("end of data block");
    serde_json::from_str(&html[start..end]).expect("data block is JSON")
}

/// Depth at pixel (i, j) of a view record, decoded as the page documents its levels.
fn depth_at(view: &serde_json::Value, i: usize, j: usize) -> Option<f64> {
    let depth = &view["depth"];
    let bytes = BASE64.decode(depth["levels"].as_str().unwrap()).unwrap();
    let at = 2 * (j * view["width"].as_u64().unwrap() as usize + i);
    let q = u16::from_le_bytes([bytes[at], bytes[at + 1]]);
    let (near, far) = (
        depth["near"].as_f64().unwrap(),
        depth["far"].as_f64().unwrap(),
    );
    (q != 0).then(|| near * (far / near).powf(f64::from(q - 1) / 65534.0))
}

/// The world point of pixel (i, j) from the view record's camera (its 4×4 world-to-camera
/// matrix, inverted here) and its depth.
fn unproject(view: &serde_json::Value, i: usize, j: usize) -> Option<[f64; 3]> {
    let z = depth_at(view, i, j)?;
    let f = |key: &str| view[key].as_f64().unwrap();
    let cam = [
        (i as f64 + 0.5 - f("cx")) / f("fx") * z,
        (j as f64 + 0.5 - f("cy")) / f("fy") * z,
        z,
    ];
    let m = |r: usize, c: usize| view["world_to_camera"][r][c].as_f64().unwrap();
    // p = Rᵀ (p_cam − t) for p_cam = R p + t.
    let d = [cam[0] - m(0, 3), cam[1] - m(1, 3), cam[2] - m(2, 3)];
    Some(std::array::from_fn(|k| {
        (0..3).map(|r| m(r, k) * d[r]).sum()
    }))
}

fn close(a: [f64; 3], b: [f64; 3], tolerance: f64) -> bool {
    a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tolerance)
}

#[test]
fn a_pixel_unprojects_to_the_point_a_closed_form_gives() {
    let scene = two_discs();
    let uploaded = DeviceScene::new(&scene, &Device::flex(), DType::F32);
    // Looking straight down from (0, 0, HEIGHT): R_wc = diag(1, −1, −1), a half turn about x.
    // Camera x is world x, camera y is world −y, camera z is world −z; a 96 × 64 picture so
    // that a mix-up of width and height or of fx and fy shows.
    let k = Intrinsics::new(90.0, 80.0, 48.0, 32.0, 96, 64).unwrap();
    let view = View {
        pose: Pose([PI, 0.0, 0.0, 0.0, 0.0, HEIGHT]),
        intrinsics: k,
    };
    let text = PageText {
        title: "two discs".into(),
        scene: "memory".into(),
        up: [0.0, 0.0, 1.0],
        max_centres: 10,
    };
    let page = views_page(&scene, &uploaded, &[(view, "top".into())], &text, &silent).unwrap();
    let data = page_data(&page.to_html().unwrap());
    let record = &data["views"][0];
    assert_eq!(data["gaussians"], 2);
    assert_eq!(data["sampled"], 2);

    // On the near disc, a few pixels off its middle: the ray through the pixel centre meets
    // the plane z = 0 (every part of a disc facing the camera lies at its centre's depth).
    for (i, j) in [(47, 31), (53, 27), (44, 35)] {
        let expected = [
            (i as f64 + 0.5 - 48.0) / 90.0 * HEIGHT,
            -(j as f64 + 0.5 - 32.0) / 80.0 * HEIGHT,
            0.0,
        ];
        let got = unproject(record, i, j).expect("a surface under the pixel");
        assert!(
            close(got, expected, 1e-4),
            "pixel ({i}, {j}): {got:?} vs {expected:?}"
        );
    }
    // The far disc, 7 below the camera: its middle projects to u = 90·(−3.5/7) + 48 = 3.
    let (i, j) = (3, 31);
    let depth = HEIGHT + 3.0;
    let expected = [
        (i as f64 + 0.5 - 48.0) / 90.0 * depth,
        -(j as f64 + 0.5 - 32.0) / 80.0 * depth,
        -3.0,
    ];
    let got = unproject(record, i, j).expect("a surface under the pixel");
    // Two depths make the levels span [4, 7]: a step of ln(7/4)/65534 relative.
    assert!(close(got, expected, 1e-4), "{got:?} vs {expected:?}");
    // A corner sees nothing.
    assert_eq!(depth_at(record, 95, 0), None);
    // The camera as trajectory.json has it.
    let pose: Vec<f64> = serde_json::from_value(record["pose"].clone()).unwrap();
    assert_eq!(pose, vec![PI, 0.0, 0.0, 0.0, 0.0, HEIGHT]);
}

#[test]
fn counts_are_marked_as_estimates_when_the_centres_are_sampled() {
    let scene = demo_scene(&DemoConfig {
        gaussians: 3000,
        seed: 1,
    })
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("demo.ply");
    write_inria_ply(&scene, &path).unwrap();
    let out = dir.path().join("views.html");
    let request = ViewsPageRequest {
        scene: path.clone(),
        out: out.clone(),
        read: ReadOptions::default(),
        options: ViewsPageOptions {
            views: 3,
            size: 64,
            max_centres: 1000,
            ..ViewsPageOptions::default()
        },
        max_memory_gb: None,
    };
    let written = write_views_page(&request, &Device::flex(), &silent).unwrap();
    assert_eq!(written.centres, 1000);
    assert_eq!(written.gaussians, 3000);
    assert!(written.around + written.inside >= 1);
    let html = std::fs::read_to_string(&out).unwrap();
    assert_eq!(html.len(), written.bytes);
    assert!(html.contains("counts are estimates scaled from them"));
    // The strip: the demo room (z up) for its guess and the two next candidates, distinct.
    assert_eq!(written.up_choices.len(), 3, "{:?}", written.up_choices);
    assert_eq!(written.up_choices[0], written.up.up);
    assert_eq!(html.matches("<figure class=\"up-choice").count(), 3);
    assert_eq!(html.matches("data-in-use=\"true\"").count(), 1);
    assert!(
        html.contains("data-copy=\"up = [0, 0, 1]\""),
        "the guess's line"
    );
    let data = page_data(&html);
    assert_eq!(data["sampled"], 1000);
    assert_eq!(
        data["views"].as_array().unwrap().len(),
        written.around + written.inside
    );
    // Only the page in the folder: no temporary file left beside it.
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
}

#[test]
fn bad_requests_name_the_file_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let request = |scene: &std::path::Path, out: &std::path::Path| ViewsPageRequest {
        scene: scene.to_path_buf(),
        out: out.to_path_buf(),
        read: ReadOptions::default(),
        options: ViewsPageOptions::default(),
        max_memory_gb: None,
    };
    let out = dir.path().join("views.html");
    let missing = dir.path().join("missing.ply");
    let error = write_views_page(&request(&missing, &out), &Device::flex(), &silent)
        .unwrap_err()
        .to_string();
    assert!(error.contains("missing.ply"), "{error}");
    assert!(!out.exists());

    let garbage = dir.path().join("garbage.ply");
    std::fs::write(
        &garbage,
        b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n",
    )
    .unwrap();
    let error = format!(
        "{:#}",
        write_views_page(&request(&garbage, &out), &Device::flex(), &silent).unwrap_err()
    );
    assert!(error.contains("garbage.ply"), "{error}");
    assert!(!out.exists());

    let nowhere = dir.path().join("no/such/folder/views.html");
    let error = write_views_page(&request(&garbage, &nowhere), &Device::flex(), &silent)
        .unwrap_err()
        .to_string();
    assert!(error.contains("does not exist"), "{error}");

    let error = write_views_page(&request(&garbage, &garbage), &Device::flex(), &silent)
        .unwrap_err()
        .to_string();
    assert!(error.contains("is the scene file itself"), "{error}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}
