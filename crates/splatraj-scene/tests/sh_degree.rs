//! `Scene::with_sh_degree`: lowering the degree keeps each Gaussian's first coefficients (and
//! so its base colour), raising it adds zeros after them, and raising then lowering gives the
//! scene back. The expected positions are computed here from the documented layout
//! `[Gaussian][coefficient][channel]`, not taken from the code.

use splatraj_scene::Scene;

/// Five Gaussians of degree 2 whose coefficient k of channel c is 100·i + 10·k + c.
fn scene() -> Scene {
    let mut scene = Scene {
        sh_degree: 2,
        ..Scene::default()
    };
    for i in 0..5 {
        scene.means.push([i as f32, 0.0, 0.0]);
        scene.scales.push([0.1; 3]);
        scene.rotations.push([1.0, 0.0, 0.0, 0.0]);
        scene.opacities.push(0.5);
        for k in 0..9 {
            for c in 0..3 {
                scene.sh.push((100 * i + 10 * k + c) as f32);
            }
        }
    }
    scene
}

fn coefficient(i: usize, k: usize, c: usize) -> f32 {
    (100 * i + 10 * k + c) as f32
}

#[test]
fn a_lower_degree_keeps_the_first_coefficients_and_a_higher_one_adds_zeros() {
    for degree in 0..=3u8 {
        let changed = scene().with_sh_degree(degree);
        let per_channel = (usize::from(degree) + 1).pow(2);
        assert_eq!(changed.sh_degree, degree);
        assert_eq!(changed.sh.len(), 5 * per_channel * 3, "degree {degree}");
        for i in 0..5 {
            for k in 0..per_channel {
                for c in 0..3 {
                    let want = if k < 9 { coefficient(i, k, c) } else { 0.0 };
                    assert_eq!(
                        changed.sh[(i * per_channel + k) * 3 + c],
                        want,
                        "degree {degree}, Gaussian {i}, coefficient {k}, channel {c}"
                    );
                }
            }
            assert_eq!(changed.base_color(i), scene().base_color(i));
        }
        assert_eq!(changed.means, scene().means, "only the SH change");
    }
}

#[test]
fn raising_then_lowering_gives_the_scene_back() {
    assert_eq!(scene().with_sh_degree(3).with_sh_degree(2), scene());
    assert_eq!(scene().with_sh_degree(2), scene());
}
