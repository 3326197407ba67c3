//! Tests of the reference renderer against closed forms worked out by hand from
//! docs/conventions.md's rules, never against the renderer's own intermediate values.

use splatraj_render::camera::Intrinsics;
use splatraj_render::reference::{RefCamera, RefChannels, RefImage, render_reference};
use splatraj_scene::Scene;

/// C0 = 1/(2·sqrt(π)), derived here rather than copied from the renderer.
fn c0() -> f64 {
    0.5 / std::f64::consts::PI.sqrt()
}

/// C1 = sqrt(3/(4π)), the degree-1 real SH constant.
fn c1() -> f64 {
    (3.0 / (4.0 * std::f64::consts::PI)).sqrt()
}

/// One Gaussian of a test scene.
#[derive(Clone)]
struct G {
    mean: [f32; 3],
    scale: [f32; 3],
    rot: [f32; 4],
    opacity: f32,
    /// `[coefficient][channel]` flat, `(degree + 1)² · 3` values.
    sh: Vec<f32>,
}

impl G {
    /// An isotropic degree-0 Gaussian with DC coefficients `dc`.
    fn iso(mean: [f32; 3], s: f32, opacity: f32, dc: [f32; 3]) -> Self {
        Self {
            mean,
            scale: [s; 3],
            rot: [1.0, 0.0, 0.0, 0.0],
            opacity,
            sh: dc.to_vec(),
        }
    }
}

fn scene_of(gs: &[G], degree: u8) -> Scene {
    Scene {
        means: gs.iter().map(|g| g.mean).collect(),
        scales: gs.iter().map(|g| g.scale).collect(),
        rotations: gs.iter().map(|g| g.rot).collect(),
        opacities: gs.iter().map(|g| g.opacity).collect(),
        sh_degree: degree,
        sh: gs.iter().flat_map(|g| g.sh.iter().copied()).collect(),
        ..Default::default()
    }
}

/// Camera at the world origin looking down +z (camera frame = world frame).
fn identity_camera(size: usize, f: f64, c: f64) -> RefCamera {
    RefCamera {
        k: intrinsics(f, f, c, c, size, size),
        rotation_cw: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation_cw: [0.0; 3],
        near: 0.01,
    }
}

fn all_channels<'a>(masks: Vec<&'a [f32]>) -> RefChannels<'a> {
    RefChannels {
        rgb: true,
        depth: true,
        masks,
    }
}

fn rgb_at(img: &RefImage, i: usize, j: usize) -> [f64; 3] {
    img.rgb.as_ref().unwrap()[img.index(i, j)]
}

fn assert_close(got: f64, want: f64, tol: f64, what: &str) {
    assert!(
        (got - want).abs() <= tol,
        "{what}: got {got:.17e}, want {want:.17e} (diff {:.3e})",
        (got - want).abs()
    );
}

// (a) A single isotropic Gaussian facing the camera follows the closed form
// o·exp(−½ d²/(s_px² + 0.3)), s_px = fx·s/z, and its centre pixel equals o·colour exactly.
#[test]
fn single_isotropic_gaussian_matches_closed_form() {
    let (o, s, z, f) = (0.75f32, 0.05f32, 5.0f32, 100.0);
    // A non-trivial unit quaternion: an isotropic Gaussian must not care about its rotation.
    let q = {
        let v = [0.8f64, -0.3, 0.5, 0.2];
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        v.map(|x| (x / n) as f32)
    };
    let mut g = G::iso([0.0, 0.0, z], s, o, [0.0; 3]); // DC 0 → colour 0.5 exactly
    g.rot = q;
    let scene = scene_of(&[g], 0);
    // cx = 32.5 puts the projected mean exactly on the centre of pixel (32, 32).
    let cam = identity_camera(64, f, 32.5);
    let img = render_reference(&scene, &cam, &all_channels(vec![&[1.0]]));

    let o = f64::from(o);
    let k = img.index(32, 32);
    assert_eq!(img.alpha[k], o, "alpha at the centre is o exactly");
    assert_eq!(rgb_at(&img, 32, 32), [0.5 * o; 3], "rgb at the centre");
    assert_eq!(
        img.depth.as_ref().unwrap()[k],
        o * f64::from(z),
        "depth at the centre"
    );
    assert_eq!(img.masks[0][k], o, "mask at the centre");

    let s_px = f * f64::from(s) / f64::from(z);
    let var = s_px * s_px + 0.3;
    for (dx, dy) in [
        (1i32, 0i32),
        (0, 1),
        (-1, 0),
        (2, 1),
        (-3, 2),
        (3, 3),
        (0, -4),
    ] {
        let d2 = f64::from(dx * dx + dy * dy);
        let mut want = o * (-0.5 * d2 / var).exp();
        if want < 1.0 / 255.0 {
            want = 0.0; // skipped as too faint
        }
        let (i, j) = ((32 + dx) as usize, (32 + dy) as usize);
        let tol = 1e-12;
        assert_close(
            img.alpha[img.index(i, j)],
            want,
            tol,
            &format!("alpha at {dx},{dy}"),
        );
        assert_close(
            rgb_at(&img, i, j)[1],
            0.5 * want,
            tol,
            &format!("g at {dx},{dy}"),
        );
    }
}

// (a, continued) The tile rule: a Gaussian whose 3-sigma square ends exactly on a tile
// boundary does not reach the next tile, even where its alpha would be above 1/255.
#[test]
fn gaussian_contributes_only_to_tiles_its_square_touches() {
    let (z, f) = (5.0f32, 100.0);
    // Σ_2D = σ² I with σ = 2.66: 3σ = 7.98, so radius = 8.
    let s = ((2.66f64 * 2.66 - 0.3).sqrt() * f64::from(z) / f) as f32;
    let o = 0.99f32;
    let scene = scene_of(&[G::iso([0.0, 0.0, z], s, o, [0.0; 3])], 0);
    // The mean projects to (24, 24): the square is [16, 32]², i.e. exactly tile (1, 1).
    let cam = identity_camera(64, f, 24.0);
    let img = render_reference(&scene, &cam, &all_channels(vec![]));

    let s_px = f * f64::from(s) / f64::from(z);
    let var = s_px * s_px + 0.3;
    let radius = (3.0 * var.sqrt()).ceil();
    assert_eq!(radius, 8.0, "test set-up: the radius must be 8");
    let value = |dx: f64, dy: f64| f64::from(o) * (-0.5 * (dx * dx + dy * dy) / var).exp();

    // Pixel 31 (centre 31.5) is in tile 1: closed form. Pixel 32 (centre 32.5) is in tile 2,
    // which the square [16, 32] does not touch: its alpha would be ≥ 1/255 but it is 0.
    let j = 23; // centre 23.5, dy = 0.5
    let inside = value(7.5, 0.5);
    assert_close(img.alpha[img.index(31, j)], inside, 1e-12, "pixel 31");
    let outside = value(8.5, 0.5);
    assert!(
        outside >= 1.0 / 255.0,
        "test set-up: pixel 32 must not be too faint"
    );
    assert_eq!(
        img.alpha[img.index(32, j)],
        0.0,
        "pixel 32 is in an untouched tile"
    );
    // Same below (rows) and on the low side: tile 0 ends at 16 where the square starts.
    assert_eq!(
        img.alpha[img.index(j, 32)],
        0.0,
        "row 32 is in an untouched tile"
    );
    assert_eq!(
        img.alpha[img.index(15, j)],
        0.0,
        "pixel 15 is in an untouched tile"
    );
    assert_close(
        img.alpha[img.index(16, j)],
        value(7.5, 0.5),
        1e-12,
        "pixel 16",
    );
}

// An anisotropic Gaussian rotated about the optical axis: Σ_2D = (f/z)² R diag(sx², sy²) Rᵀ
// + 0.3 I (the z scale does not project at the image centre), evaluated with a hand inverse.
#[test]
fn rotated_anisotropic_gaussian_matches_closed_form() {
    let (z, f, theta) = (5.0f32, 100.0, 0.6f64);
    let (sx, sy, sz) = (0.1f32, 0.03f32, 0.07f32);
    let q = [
        (theta / 2.0).cos() as f32,
        0.0,
        0.0,
        (theta / 2.0).sin() as f32,
    ];
    let o = 0.9f32;
    let g = G {
        mean: [0.0, 0.0, z],
        scale: [sx, sy, sz],
        rot: q,
        opacity: o,
        sh: vec![0.0; 3],
    };
    let scene = scene_of(&[g], 0);
    let cam = identity_camera(64, f, 32.5);
    let img = render_reference(&scene, &cam, &all_channels(vec![]));

    // The quaternion is stored in f32: use the angle it really encodes.
    let th = 2.0 * f64::from(q[3]).atan2(f64::from(q[0]));
    let (c, s) = (th.cos(), th.sin());
    let k = f / f64::from(z);
    let (vx, vy) = ((k * f64::from(sx)).powi(2), (k * f64::from(sy)).powi(2));
    // R diag(vx, vy) Rᵀ with R = [[c, −s], [s, c]] (local x goes to (c, s)).
    let a = c * c * vx + s * s * vy + 0.3;
    let b = c * s * (vx - vy);
    let d = s * s * vx + c * c * vy + 0.3;
    let det = a * d - b * b;
    for (dx, dy) in [(3i32, 2i32), (3, -2), (-2, 1), (0, 5), (6, 4), (4, -1)] {
        // d = mean − pixel centre = (−dx, −dy); the quadratic form is even, so the sign is moot.
        let (ex, ey) = (f64::from(dx), f64::from(dy));
        let power = -0.5 * (d * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / det;
        let mut want = (f64::from(o) * power.exp()).min(0.99);
        if want < 1.0 / 255.0 {
            want = 0.0;
        }
        let (i, j) = ((32 + dx) as usize, (32 + dy) as usize);
        assert_close(
            img.alpha[img.index(i, j)],
            want,
            1e-12,
            &format!("{dx},{dy}"),
        );
    }
    // The elongation is along (c, s): the pixel at +3·(c, s) is brighter than at +3·(c, −s).
    assert!(img.alpha[img.index(35, 34)] > img.alpha[img.index(35, 30)]);
}

// Off-axis Gaussian beyond 1.3·tan(half fov): the Jacobian uses the clamped x/z while the mean
// keeps its true (off-screen) position.
#[test]
fn jacobian_uses_clamped_tangent_but_mean_is_not_clamped() {
    let (f, z, x, s, o) = (100.0, 2.0f32, 1.0f32, 0.2f32, 0.8f32);
    let scene = scene_of(&[G::iso([x, 0.0, z], s, o, [0.0; 3])], 0);
    let cam = identity_camera(64, f, 32.5);
    let img = render_reference(&scene, &cam, &all_channels(vec![]));

    let lim = 1.3 * 0.5 * 64.0 / f; // 0.416 < x/z = 0.5
    let xh = (f64::from(x) / f64::from(z)).min(lim);
    let k = f / f64::from(z);
    let s2 = f64::from(s).powi(2);
    // J = [[k, 0, −k·x̂], [0, k, 0]], Σ_cam = s² I → Σ_2D = s² k² diag(1 + x̂², 1) + 0.3 I.
    let var_x = s2 * k * k * (1.0 + xh * xh) + 0.3;
    let var_y = s2 * k * k + 0.3;
    let u = f * f64::from(x) / f64::from(z) + 32.5; // 82.5: off screen, not clamped
    for (i, j) in [(63usize, 32usize), (60, 30), (55, 36), (50, 20)] {
        let (dx, dy) = (u - (i as f64 + 0.5), 32.5 - (j as f64 + 0.5));
        let want = f64::from(o) * (-0.5 * (dx * dx / var_x + dy * dy / var_y)).exp();
        let want = if want < 1.0 / 255.0 { 0.0 } else { want };
        assert_close(
            img.alpha[img.index(i, j)],
            want,
            1e-12,
            &format!("pixel {i},{j}"),
        );
    }
}

// (b) Compositing order is by depth, not by file order.
#[test]
fn two_gaussians_composite_front_to_back_whatever_their_order() {
    let near = G::iso([0.0, 0.0, 4.0], 0.2, 0.5, [1.5, -1.0, 0.0]);
    let far = G::iso([0.0, 0.0, 6.0], 0.3, 0.6, [-1.0, 1.5, 0.5]);
    let cam = identity_camera(64, 100.0, 32.5);
    let masks_a: [f32; 2] = [1.0, 0.0]; // marks the near Gaussian
    let masks_b: [f32; 2] = [0.0, 1.0];
    let a = render_reference(
        &scene_of(&[near.clone(), far.clone()], 0),
        &cam,
        &all_channels(vec![&masks_a]),
    );
    let b = render_reference(
        &scene_of(&[far.clone(), near.clone()], 0),
        &cam,
        &all_channels(vec![&masks_b]),
    );
    assert_eq!(a, b, "swapping the file order must not change the image");

    // Centre pixel: both Gaussians have exp(0) = 1 there.
    let colour =
        |g: &G| -> [f64; 3] { std::array::from_fn(|c| (0.5 + c0() * f64::from(g.sh[c])).max(0.0)) };
    let (an, af) = (f64::from(near.opacity), f64::from(far.opacity));
    let (cn, cf) = (colour(&near), colour(&far));
    let got = rgb_at(&a, 32, 32);
    for c in 0..3 {
        let want = cn[c] * an + cf[c] * af * (1.0 - an);
        let wrong = cf[c] * af + cn[c] * an * (1.0 - af);
        assert_close(got[c], want, 1e-12, &format!("channel {c}"));
        if c < 2 {
            assert!(
                (want - wrong).abs() > 1e-2,
                "test set-up: orders must differ"
            );
        }
    }
    let k = a.index(32, 32);
    assert_close(
        a.depth.as_ref().unwrap()[k],
        4.0 * an + 6.0 * af * (1.0 - an),
        1e-12,
        "depth",
    );
    assert_close(a.masks[0][k], an, 1e-15, "mask of the near Gaussian");
    assert_close(a.alpha[k], 1.0 - (1.0 - an) * (1.0 - af), 1e-15, "alpha");
}

// (c) Early termination: the pixel stops before the Gaussian that would bring T below 1e-4,
// and nothing behind it counts even if it would not.
#[test]
fn opaque_stack_stops_after_the_right_number() {
    let cam = identity_camera(64, 100.0, 32.5);
    let stack = |opacities: &[f32]| -> Vec<G> {
        opacities
            .iter()
            .enumerate()
            .map(|(k, &o)| G::iso([0.0, 0.0, 2.0 + k as f32], 0.1, o, [0.0; 3]))
            .collect()
    };
    let one_hot = |n: usize| -> Vec<Vec<f32>> {
        (0..n)
            .map(|k| (0..n).map(|i| f32::from(u8::from(i == k))).collect())
            .collect()
    };

    // o = 1 → α = 0.99 (clamped). By hand: T = 1 → 0.01 → 1e-4 (not < 1e-4, so included)
    // → 1e-6 (< 1e-4: stop). Two Gaussians count.
    let scene = scene_of(&stack(&[1.0; 4]), 0);
    let masks = one_hot(4);
    let img = render_reference(
        &scene,
        &cam,
        &all_channels(masks.iter().map(Vec::as_slice).collect()),
    );
    let k = img.index(32, 32);
    let a = 0.99;
    assert_close(img.masks[0][k], a, 1e-15, "layer 1");
    assert_close(img.masks[1][k], a * (1.0 - a), 1e-15, "layer 2");
    assert_eq!(img.masks[2][k], 0.0, "layer 3 is past the stop");
    assert_eq!(img.masks[3][k], 0.0, "layer 4 is past the stop");
    assert_close(img.alpha[k], 1.0 - 1e-4, 1e-15, "alpha = 1 − T after two");
    assert_close(
        img.depth.as_ref().unwrap()[k],
        2.0 * a + 3.0 * a * (1.0 - a),
        1e-12,
        "depth",
    );

    // o = 0.95: T = 0.05, 0.0025, 1.25e-4, then 6.25e-6 < 1e-4 → stop after three. The fifth
    // layer (α = 0.1) would keep T at 1.125e-4 ≥ 1e-4 but the pixel has already stopped.
    let ops = [0.95f32, 0.95, 0.95, 0.95, 0.1];
    let scene = scene_of(&stack(&ops), 0);
    let masks = one_hot(5);
    let img = render_reference(
        &scene,
        &cam,
        &all_channels(masks.iter().map(Vec::as_slice).collect()),
    );
    let a = f64::from(0.95f32);
    let mut t = 1.0;
    for layer in 0..3 {
        assert_close(img.masks[layer][k], a * t, 1e-15, &format!("layer {layer}"));
        t *= 1.0 - a;
    }
    assert_eq!(img.masks[3][k], 0.0, "layer 4 would bring T below 1e-4");
    assert_eq!(img.masks[4][k], 0.0, "layer 5 is behind the stop");
    assert_close(img.alpha[k], 1.0 - (1.0 - a).powi(3), 1e-15, "alpha");
}

// (d) Gaussians behind the camera or the near plane are culled, not clamped.
#[test]
fn gaussians_behind_the_near_plane_contribute_nothing() {
    let mut cam = identity_camera(32, 50.0, 16.0);
    let big = |z: f32| G::iso([0.0, 0.0, z], 3.0, 0.9, [1.0; 3]);
    let ch = RefChannels {
        rgb: true,
        depth: true,
        masks: vec![],
    };
    // Control: in front, the same Gaussian covers the image (so the test can fail).
    let front = render_reference(&scene_of(&[big(5.0)], 0), &cam, &ch);
    assert!(front.alpha.iter().all(|&a| a > 0.5));

    for z in [-5.0f32, -0.001, 0.0, 0.005] {
        let img = render_reference(&scene_of(&[big(z)], 0), &cam, &ch);
        assert!(img.alpha.iter().all(|&a| a == 0.0), "z = {z}: alpha");
        assert!(
            img.rgb.unwrap().iter().all(|p| *p == [0.0; 3]),
            "z = {z}: rgb"
        );
        assert!(
            img.depth.unwrap().iter().all(|&d| d == 0.0),
            "z = {z}: depth"
        );
    }
    // Exactly on the near plane is culled (z ≤ near); just past it is not.
    cam.near = 0.5;
    let on = render_reference(&scene_of(&[big(0.5)], 0), &cam, &ch);
    assert!(on.alpha.iter().all(|&a| a == 0.0), "z = near is culled");
    let past = render_reference(&scene_of(&[big(0.5001)], 0), &cam, &ch);
    assert!(
        past.alpha.iter().any(|&a| a > 0.0),
        "z just past near is drawn"
    );

    // Behind a moved camera too: a camera at z = 10 looking toward +z sees nothing at z = 5.
    let cam = RefCamera::look_at(
        [0.0, 0.0, 10.0],
        [0.0, 0.0, 20.0],
        [0.0, -1.0, 0.0],
        intrinsics(50.0, 50.0, 16.0, 16.0, 32, 32),
    );
    let img = render_reference(&scene_of(&[big(5.0)], 0), &cam, &ch);
    assert!(img.alpha.iter().all(|&a| a == 0.0));
}

// (e) The degree-1 SH terms change the colour with the view direction as
// colour = 0.5 − C1·y·k1 + C1·z·k2 − C1·x·k3 predicts (INRIA's basis and signs).
#[test]
fn sh_degree_one_follows_view_direction() {
    let (k1, k2, k3) = (0.8f32, -0.7f32, 0.9f32);
    // [coefficient][channel]: DC 0; coefficient 1 (y) on red, 2 (z) on green, 3 (x) on blue.
    let sh = vec![0.0, 0.0, 0.0, k1, 0.0, 0.0, 0.0, k2, 0.0, 0.0, 0.0, k3];
    let o = 0.5f32;
    let g = G {
        mean: [0.2, -0.1, 0.3],
        scale: [0.01; 3],
        rot: [1.0, 0.0, 0.0, 0.0],
        opacity: o,
        sh,
    };
    let scene = scene_of(std::slice::from_ref(&g), 1);
    let mean = g.mean.map(f64::from);
    let eyes = [
        [3.0, 0.0, 0.0],
        [-3.0, 0.0, 0.0],
        [0.0, 3.0, 0.0],
        [0.0, -3.0, 0.0],
        [0.0, 0.0, 3.0],
        [0.0, 0.0, -3.0],
        [1.5, -2.0, 2.5],
    ];
    let mut reds = vec![];
    for offset in eyes {
        let eye = [
            mean[0] + offset[0],
            mean[1] + offset[1],
            mean[2] + offset[2],
        ];
        let up = if offset[0] == 0.0 && offset[2] == 0.0 {
            [0.0, 0.0, 1.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let cam = RefCamera::look_at(eye, mean, up, intrinsics(100.0, 100.0, 32.5, 32.5, 64, 64));
        let img = render_reference(&scene, &cam, &all_channels(vec![]));
        let n = offset.iter().map(|c| c * c).sum::<f64>().sqrt();
        let [dx, dy, dz] = offset.map(|c| -c / n); // mean − eye, normalised
        let want = [
            0.5 - c1() * dy * f64::from(k1),
            0.5 + c1() * dz * f64::from(k2),
            0.5 - c1() * dx * f64::from(k3),
        ];
        let got = rgb_at(&img, 32, 32);
        for c in 0..3 {
            assert_close(
                got[c],
                f64::from(o) * want[c],
                1e-12,
                &format!("eye {offset:?} ch {c}"),
            );
        }
        reds.push(got[0]);
    }
    assert!(
        (reds[2] - reds[3]).abs() > 0.3,
        "red must change between ±y views"
    );

    // Negative results clamp to 0 per channel: k = 2 seen from −y gives 0.5 − C1·2 < 0.
    let mut strong = g;
    strong.sh[3] = 2.0;
    let scene = scene_of(&[strong], 1);
    let eye = [mean[0], mean[1] - 3.0, mean[2]]; // dir = +y
    let cam = RefCamera::look_at(
        eye,
        mean,
        [0.0, 0.0, 1.0],
        intrinsics(100.0, 100.0, 32.5, 32.5, 64, 64),
    );
    let img = render_reference(&scene, &cam, &all_channels(vec![]));
    assert_eq!(rgb_at(&img, 32, 32)[0], 0.0);
}

// (f) look_at: the target projects to (cx, cy), the frame is a proper rotation and world up
// points to image −y.
#[test]
fn look_at_centres_the_target_and_keeps_up_up() {
    let cases: [([f64; 3], [f64; 3], [f64; 3]); 5] = [
        ([0.0, 0.0, -5.0], [0.0, 0.0, 0.0], [0.0, -1.0, 0.0]),
        ([3.0, 2.0, 1.0], [0.5, -0.5, 0.2], [0.0, 0.0, 1.0]),
        ([-4.0, 1.0, 2.0], [1.0, 1.0, 1.0], [0.0, 1.0, 0.0]),
        ([1.0, -2.0, 6.0], [0.0, 0.3, 0.0], [0.0, -1.0, 0.0]),
        ([2.0, 2.0, 2.0], [0.0, 0.0, 0.0], [0.3, 0.2, 0.9]),
    ];
    for (eye, target, up) in cases {
        let cam = RefCamera::look_at(
            eye,
            target,
            up,
            intrinsics(200.0, 180.0, 160.0, 120.0, 320, 240),
        );
        let r = cam.rotation_cw;
        // Proper rotation: orthonormal rows, determinant +1.
        for a in 0..3 {
            for b in 0..3 {
                let dot: f64 = (0..3).map(|k| r[a][k] * r[b][k]).sum();
                assert_close(dot, f64::from(u8::from(a == b)), 1e-12, "RRᵀ = I");
            }
        }
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        assert_close(det, 1.0, 1e-12, "det R");

        let project = |p: [f64; 3]| -> (f64, f64, f64) {
            let q: [f64; 3] = std::array::from_fn(|a| {
                (0..3).map(|k| r[a][k] * p[k]).sum::<f64>() + cam.translation_cw[a]
            });
            (
                cam.k.fx * q[0] / q[2] + cam.k.cx,
                cam.k.fy * q[1] / q[2] + cam.k.cy,
                q[2],
            )
        };
        let (u, v, z) = project(target);
        assert!(z > 0.0, "target in front");
        assert_close(u, cam.k.cx, 1e-9, "target u");
        assert_close(v, cam.k.cy, 1e-9, "target v");
        // The eye maps to the camera origin and center() gives it back.
        for (row, t) in r.iter().zip(cam.translation_cw) {
            let q = (0..3).map(|k| row[k] * eye[k]).sum::<f64>() + t;
            assert_close(q, 0.0, 1e-12, "eye at the camera origin");
        }
        let c = cam.center();
        for k in 0..3 {
            assert_close(c[k], eye[k], 1e-12, "center() = eye");
        }

        // Up: the camera's x axis is perpendicular to world up and its −y axis leans up.
        let n = up.iter().map(|c| c * c).sum::<f64>().sqrt();
        let up = up.map(|c| c / n);
        let x_dot_up: f64 = (0..3).map(|k| r[0][k] * up[k]).sum();
        let minus_y_dot_up: f64 = (0..3).map(|k| -r[1][k] * up[k]).sum();
        assert_close(x_dot_up, 0.0, 1e-12, "no roll");
        assert!(minus_y_dot_up > 0.0, "image up leans to world up");
        // A point just above the target lands above the image centre (smaller v).
        let above = [
            target[0] + 0.1 * up[0],
            target[1] + 0.1 * up[1],
            target[2] + 0.1 * up[2],
        ];
        let (u, v, _) = project(above);
        assert!(v < cam.k.cy, "above the target is up in the image");
        assert_close(
            u,
            cam.k.cx,
            1e-9,
            "above the target stays on the vertical centre line",
        );
    }
}

// Only the channels asked for are produced, and a colour-only render agrees with a full one.
#[test]
fn channels_are_independent() {
    let gs = [
        G::iso([0.1, 0.0, 3.0], 0.2, 0.7, [0.3, 0.1, -0.2]),
        G::iso([-0.2, 0.1, 4.0], 0.3, 0.6, [-0.5, 0.4, 0.9]),
    ];
    let scene = scene_of(&gs, 0);
    let cam = identity_camera(48, 80.0, 24.0);
    let full = render_reference(&scene, &cam, &all_channels(vec![&[1.0, 0.0]]));
    let only = render_reference(
        &scene,
        &cam,
        &RefChannels {
            rgb: true,
            ..Default::default()
        },
    );
    assert!(only.depth.is_none() && only.masks.is_empty());
    assert_eq!(only.rgb, full.rgb);
    assert_eq!(only.alpha, full.alpha);
    let bytes = only.rgb8().unwrap();
    assert_eq!(bytes.len(), 48 * 48 * 3);
}

/// Intrinsics with these values, checked.
fn intrinsics(fx: f64, fy: f64, cx: f64, cy: f64, width: usize, height: usize) -> Intrinsics {
    Intrinsics::new(fx, fy, cx, cy, width, height).unwrap()
}
