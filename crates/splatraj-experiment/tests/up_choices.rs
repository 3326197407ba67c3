//! The views page's "Which way is up?" choices: the up in use first, then the geometry's
//! candidates not along it; their `[scene]` lines; and the cameras that take their pictures
//! stand upright for each up.

use glam::DVec3;
use splatraj_experiment::picking::up_choices::{up_line, up_options, upright_view};
use splatraj_report::views_page::up_strip::InUse;
use splatraj_scene::up_axis::{ResolvedUp, UpCandidate, UpCandidates, UpMethod};
use splatraj_scene::{CamerasUp, Scene, UpSource};

fn candidates() -> UpCandidates {
    let c = |up: [f32; 3], score| UpCandidate { up, raw: up, score };
    UpCandidates {
        method: UpMethod::Normals,
        ranked: [
            c([0.0, -1.0, 0.0], 0.6),
            c([0.0, 0.0, 1.0], 0.3),
            c([1.0, 0.0, 0.0], 0.1),
        ],
    }
}

fn resolved(up: [f64; 3], source: UpSource) -> ResolvedUp {
    ResolvedUp {
        up,
        source,
        guess: (source == UpSource::Guess).then(|| candidates().guess()),
        cameras: None,
    }
}

#[test]
fn the_guess_comes_first_then_its_two_next_candidates() {
    let c = candidates();
    let options = up_options(&resolved([0.0, -1.0, 0.0], UpSource::Guess), Some(&c));
    let ups: Vec<_> = options.iter().map(|o| o.up).collect();
    assert_eq!(
        ups,
        vec![[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]
    );
    assert_eq!(options[0].in_use, InUse::Yes);
    assert!(options[0].why.contains("score 0.60"), "{:?}", options[0]);
    assert!(
        options[2].why.contains("third candidate"),
        "{:?}",
        options[2]
    );
}

#[test]
fn an_up_given_along_a_candidate_leaves_it_out() {
    // Given +y (the guess upside down): the guess is that picture turned, so the strip
    // shows the given up and the two others.
    let c = candidates();
    let options = up_options(&resolved([0.0, 1.0, 0.0], UpSource::Config), Some(&c));
    let ups: Vec<_> = options.iter().map(|o| o.up).collect();
    assert_eq!(ups, vec![[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]);
    assert!(
        options[0].why.contains("the geometry guesses [0, -1, 0]"),
        "{:?}",
        options[0]
    );
}

#[test]
fn cameras_come_first_with_their_agreement_and_the_geometry_after() {
    let c = candidates();
    let cameras = ResolvedUp::from(CamerasUp {
        up: [0.0, -1.0, 0.0],
        cameras: 60,
        spread_degrees: 5.5,
        file: "cameras.json".into(),
    });
    let options = up_options(&cameras, Some(&c));
    let ups: Vec<_> = options.iter().map(|o| o.up).collect();
    assert_eq!(
        ups,
        vec![[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]
    );
    assert_eq!(
        options[0].why,
        "from the capture's 60 cameras in cameras.json: 90 % of their horizons within 5.5° of \
         level; the geometry's guess agrees"
    );
    assert!(
        options[1].why.contains("second candidate"),
        "{:?}",
        options[1]
    );
}

#[test]
fn lines_are_whole_where_exact_and_never_minus_zero() {
    assert_eq!(up_line([0.0, -1.0, 0.0]), "up = [0, -1, 0]");
    assert_eq!(up_line([-0.0, 0.0, 1.0]), "up = [0, 0, 1]");
    assert_eq!(
        up_line([0.6, 0.8, 0.0].map(|v: f64| -v)),
        "up = [-0.6000, -0.8000, 0]"
    );
}

/// Two splats at opposite corners of a box 2 × 0.4 × 1 centred on the origin.
fn two_splats() -> Scene {
    Scene {
        means: vec![[-1.0, -0.2, -0.5], [1.0, 0.2, 0.5]],
        scales: vec![[0.1; 3]; 2],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; 2],
        opacities: vec![0.9; 2],
        sh: vec![0.0; 6],
        ..Scene::default()
    }
}

#[test]
fn the_view_stands_upright_for_its_up_and_sees_the_box() {
    let scene = two_splats();
    for up in [[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]] {
        let view = upright_view(&scene, up, None, 60.0, 64).unwrap();
        let r = view.pose.rotation_wc();
        // The image's up (camera −y) leans toward `up` and has no roll: camera x is level.
        let image_up = -(r * DVec3::Y);
        assert!(image_up.dot(DVec3::from(up)) > 0.9, "{up:?}: {image_up}");
        assert!((r * DVec3::X).dot(DVec3::from(up)).abs() < 1e-9);
        // It looks down at the box's centre from above its horizon.
        let forward = r * DVec3::Z;
        assert!(forward.dot(DVec3::from(up)) < -0.3, "{up:?}: {forward}");
        assert!((forward.cross(-view.pose.centre())).length() < 1e-6);
    }
}

#[test]
fn a_candidate_is_seen_across_the_up_in_use() {
    // Candidate +x against the up in use +z: +z runs (nearly) left to right in its picture,
    // seen from its upper side.
    let scene = two_splats();
    let view = upright_view(&scene, [1.0, 0.0, 0.0], Some([0.0, 0.0, 1.0]), 60.0, 64).unwrap();
    let r = view.pose.rotation_wc();
    let right = r * DVec3::X;
    assert!(right.dot(DVec3::Z).abs() > 0.85, "{right}");
    // From the upper side of the up in use: looking a little down along it.
    assert!((r * DVec3::Z).dot(DVec3::Z) < -0.3, "{}", r * DVec3::Z);
}
