//! Tests of the procedural demo scene against facts stated independently of the generator:
//! the published layout boxes, the requested counts, the meaning of the Gaussian parameters.

use std::collections::BTreeMap;

use splatraj_scene::Scene;
use splatraj_scene::demo::{
    DEMO_GAUSSIANS_RANGE, DEMO_UP, DEMO_VIEWPOINT, DemoConfig, DemoObject, demo_layout,
    demo_object_names, demo_scene,
};

fn build(seed: u64, gaussians: usize) -> Scene {
    demo_scene(&DemoConfig { seed, gaussians }).expect("demo scene in range builds")
}

fn ids(scene: &Scene) -> &[i32] {
    &scene
        .extras
        .labels
        .as_ref()
        .expect("demo scene has labels")
        .ids
}

fn layout_by_name(name: &str) -> DemoObject {
    demo_layout()
        .into_iter()
        .find(|o| o.name == name)
        .unwrap_or_else(|| panic!("layout has no {name:?}"))
}

/// Column `k` of the rotation matrix of the unit quaternion (w, x, y, z): where the
/// Gaussian's local axis k points in world coordinates (textbook formula, not the crate's).
fn local_axis(q: [f32; 4], k: usize) -> [f64; 3] {
    let [w, x, y, z] = q.map(f64::from);
    let r = [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ];
    [r[0][k], r[1][k], r[2][k]]
}

/// Index of the smallest scale: the Gaussian's normal axis for a flat splat.
fn thin_axis(s: [f32; 3]) -> usize {
    (0..3).min_by(|&a, &b| s[a].total_cmp(&s[b])).unwrap()
}

fn bits(scene: &Scene) -> Vec<u32> {
    let mut out = Vec::new();
    out.extend(scene.means.iter().flatten().map(|v| v.to_bits()));
    out.extend(scene.scales.iter().flatten().map(|v| v.to_bits()));
    out.extend(scene.rotations.iter().flatten().map(|v| v.to_bits()));
    out.extend(scene.opacities.iter().map(|v| v.to_bits()));
    out.extend(scene.sh.iter().map(|v| v.to_bits()));
    out
}

#[test]
fn same_seed_gives_a_bit_identical_scene() {
    let a = build(42, 20_000);
    let b = build(42, 20_000);
    assert_eq!(bits(&a), bits(&b));
    assert_eq!(a.extras, b.extras);
    assert_eq!(a.sh_degree, b.sh_degree);
}

#[test]
fn another_seed_changes_the_samples_but_not_the_layout() {
    let a = build(1, 20_000);
    let b = build(2, 20_000);
    assert_ne!(a.means, b.means);
    assert_ne!(a.sh, b.sh);
    // Same number of Gaussians per label, and each label's centroid within 2 cm.
    let stats = |s: &Scene| {
        let mut m: BTreeMap<i32, (usize, [f64; 3])> = BTreeMap::new();
        for (i, &id) in ids(s).iter().enumerate() {
            let e = m.entry(id).or_insert((0, [0.0; 3]));
            e.0 += 1;
            for k in 0..3 {
                e.1[k] += f64::from(s.means[i][k]);
            }
        }
        m
    };
    let (sa, sb) = (stats(&a), stats(&b));
    assert_eq!(sa.keys().collect::<Vec<_>>(), sb.keys().collect::<Vec<_>>());
    for (id, (na, ca)) in &sa {
        let (nb, cb) = sb[id];
        assert_eq!(*na, nb, "label {id} count changed with the seed");
        for k in 0..3 {
            let d = ca[k] / *na as f64 - cb[k] / nb as f64;
            assert!(
                d.abs() < 0.02,
                "label {id} centroid moved by {d} m on axis {k}"
            );
        }
    }
}

#[test]
fn the_count_is_exact() {
    for n in [1_000, 50_000, 77_777, 200_000] {
        let s = build(7, n);
        assert_eq!(s.len(), n);
        assert_eq!(s.scales.len(), n);
        assert_eq!(s.rotations.len(), n);
        assert_eq!(s.opacities.len(), n);
        assert_eq!(s.sh.len(), n * s.sh_coeffs() * 3);
        assert_eq!(ids(&s).len(), n);
    }
}

#[test]
fn a_count_out_of_range_is_an_error_naming_the_value_and_range() {
    assert_eq!(*DEMO_GAUSSIANS_RANGE.start(), 1_000);
    for n in [0, 999, 10_000_001] {
        let err = demo_scene(&DemoConfig {
            seed: 7,
            gaussians: n,
        })
        .expect_err("out of range")
        .to_string();
        assert!(err.contains(&format!("gaussians = {n}")), "{err}");
        assert!(err.contains("1000..=10000000"), "{err}");
    }
    let default = DemoConfig::default();
    assert_eq!((default.seed, default.gaussians), (7, 100_000));
}

#[test]
fn every_value_is_renderable_and_plausible() {
    let s = build(3, 50_000);
    assert_eq!(s.sh_degree, 1);
    assert_eq!(DEMO_UP, [0.0, 0.0, 1.0]);
    for i in 0..s.len() {
        assert!(s.means[i].iter().all(|v| v.is_finite()), "mean {i}");
        assert!(
            s.scales[i].iter().all(|v| v.is_finite() && *v > 0.0),
            "scale {i}: {:?}",
            s.scales[i]
        );
        let q = s.rotations[i];
        let norm = q.iter().map(|c| c * c).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-5, "quaternion {i} has norm {norm}");
        assert!((0.0..=1.0).contains(&s.opacities[i]), "opacity {i}");
        assert!(s.sh_of(i).iter().all(|v| v.is_finite()), "sh {i}");
        let c = s.base_color(i);
        assert!(
            c.iter().all(|v| (0.0..=1.0 + 1e-5).contains(v)),
            "colour {i}: {c:?}"
        );
    }
    // Like a real capture: mostly high opacities, some low.
    let n = s.len() as f64;
    let high = s.opacities.iter().filter(|&&o| o >= 0.6).count() as f64 / n;
    let low = s.opacities.iter().filter(|&&o| o < 0.5).count() as f64 / n;
    assert!(high > 0.7, "only {high} of opacities are >= 0.6");
    assert!(low > 0.02, "only {low} of opacities are < 0.5");
    // The view-dependent terms are present but small.
    let rest: Vec<f32> = (0..s.len())
        .flat_map(|i| s.sh_of(i)[3..].to_vec())
        .collect();
    let rms = (rest.iter().map(|v| v * v).sum::<f32>() / rest.len() as f32).sqrt();
    assert!(rms > 0.005 && rms < 0.2, "SH degree-1 rms {rms}");
}

#[test]
fn labels_name_at_least_five_objects_each_with_hundreds_of_gaussians() {
    let s = build(7, 50_000);
    let labels = s.extras.labels.as_ref().unwrap();
    assert_eq!(labels.source, "demo");
    assert_eq!(labels.names.get(&0).map(String::as_str), Some("floor"));
    assert_eq!(labels.names.get(&1).map(String::as_str), Some("walls"));
    assert_eq!(labels.names.get(&2).map(String::as_str), Some("table"));
    let objects = demo_object_names();
    assert!(objects.len() >= 5, "{objects:?}");
    let mut distinct = objects.clone();
    distinct.sort_unstable();
    distinct.dedup();
    assert_eq!(distinct.len(), objects.len(), "duplicate names");
    let counts = labels.counts();
    for name in objects {
        let id = *labels
            .names
            .iter()
            .find(|(_, n)| n.as_str() == name)
            .unwrap_or_else(|| panic!("{name} has no label"))
            .0;
        assert!(id >= 3, "{name} has a structural id {id}");
        let c = counts.get(&id).copied().unwrap_or(0);
        assert!(c >= 500, "{name} has only {c} Gaussians out of 50 000");
    }
    // Every Gaussian carries a named label.
    assert!(labels.ids.iter().all(|id| labels.names.contains_key(id)));
}

#[test]
fn every_gaussian_lies_in_its_published_box_for_any_seed_and_size() {
    let by_id: BTreeMap<i32, DemoObject> = demo_layout().iter().map(|o| (o.id, *o)).collect();
    for (seed, n) in [(12_345, 1_000), (99, 200_000), (u64::MAX, 60_000)] {
        let s = build(seed, n);
        for (i, &id) in ids(&s).iter().enumerate() {
            let o = by_id[&id];
            let (min, max, p) = (o.min(), o.max(), s.means[i]);
            assert!(
                (0..3).all(|k| p[k] >= min[k] - 1e-4 && p[k] <= max[k] + 1e-4),
                "seed {seed}, n {n}: {} Gaussian at {p:?} is outside {min:?}..{max:?}",
                o.name
            );
        }
    }
}

#[test]
fn every_gaussian_lies_in_its_published_box_and_the_boxes_are_tight() {
    let s = build(11, 100_000);
    let layout = demo_layout();
    let by_id: BTreeMap<i32, DemoObject> = layout.iter().map(|o| (o.id, *o)).collect();
    let mut lo = BTreeMap::<i32, [f32; 3]>::new();
    let mut hi = BTreeMap::<i32, [f32; 3]>::new();
    for (i, &id) in ids(&s).iter().enumerate() {
        let o = by_id[&id];
        let (min, max, p) = (o.min(), o.max(), s.means[i]);
        for k in 0..3 {
            assert!(
                p[k] >= min[k] - 1e-4 && p[k] <= max[k] + 1e-4,
                "{} Gaussian at {p:?} is outside its box {min:?}..{max:?}",
                o.name
            );
        }
        let l = lo.entry(id).or_insert([f32::MAX; 3]);
        let h = hi.entry(id).or_insert([f32::MIN; 3]);
        for k in 0..3 {
            l[k] = l[k].min(p[k]);
            h[k] = h[k].max(p[k]);
        }
    }
    // Tight: the Gaussians span nearly all of each object's box (floor: its x and y only).
    for o in &layout {
        let (l, h) = (lo[&o.id], hi[&o.id]);
        for k in 0..3 {
            if o.name == "floor" && k == 2 {
                continue;
            }
            let extent = h[k] - l[k];
            assert!(
                extent >= 0.85 * o.size[k],
                "{} spans {extent} m on axis {k} but its box is {} m",
                o.name,
                o.size[k]
            );
        }
    }
}

#[test]
fn objects_range_from_small_to_large_and_stand_on_the_table_or_floor() {
    let table_top = 0.75;
    let objects: Vec<DemoObject> = demo_layout().into_iter().filter(|o| o.id >= 3).collect();
    let largest = |o: &DemoObject| o.size.iter().copied().fold(0.0, f32::max);
    let smallest = objects.iter().map(largest).fold(f32::MAX, f32::min);
    let biggest = objects.iter().map(largest).fold(0.0, f32::max);
    assert!(smallest <= 0.13, "smallest object is {smallest} m");
    assert!(biggest >= 0.35, "largest object is {biggest} m");
    for o in &objects {
        let bottom = o.min()[2];
        let on_table = (bottom - table_top).abs() < 0.01;
        let on_floor = bottom.abs() < 0.01;
        assert!(on_table || on_floor, "{} floats at z = {bottom}", o.name);
        // Inside the 4 × 4 m room.
        assert!(o.min()[0] > -2.0 && o.max()[0] < 2.0 && o.min()[1] > -2.0 && o.max()[1] < 2.0);
    }
    // At least five objects on the table, within its 1.6 × 1.0 m top.
    let on_table: Vec<&DemoObject> = objects
        .iter()
        .filter(|o| (o.min()[2] - table_top).abs() < 0.01)
        .collect();
    assert!(on_table.len() >= 5);
    for o in on_table {
        assert!(
            o.min()[0] > -0.8 && o.max()[0] < 0.8,
            "{} overhangs",
            o.name
        );
        assert!(
            o.min()[1] > -0.5 && o.max()[1] < 0.5,
            "{} overhangs",
            o.name
        );
    }
}

#[test]
fn floor_and_wall_splats_are_flat_and_lie_in_their_planes() {
    let s = build(5, 50_000);
    let (mut floor, mut walls) = (0, 0);
    for (i, &id) in ids(&s).iter().enumerate() {
        let sc = s.scales[i];
        let k = thin_axis(sc);
        let others = (0..3)
            .filter(|&j| j != k)
            .map(|j| sc[j])
            .fold(f32::MAX, f32::min);
        let normal = local_axis(s.rotations[i], k);
        match id {
            0 => {
                floor += 1;
                assert!(
                    s.means[i][2].abs() < 1e-6,
                    "floor Gaussian at z {}",
                    s.means[i][2]
                );
                assert!(
                    normal[2].abs() > 0.999,
                    "floor Gaussian {i} normal {normal:?}"
                );
                assert!(
                    sc[k] < 0.2 * others,
                    "floor Gaussian {i} is not flat: {sc:?}"
                );
            }
            1 => {
                walls += 1;
                let p = s.means[i];
                // On the back wall (y = 2, normal ±y) or the left wall (x = −2, normal ±x).
                let axis = if (p[1] - 2.0).abs() < 1e-5 {
                    1
                } else {
                    assert!(
                        (p[0] + 2.0).abs() < 1e-5,
                        "wall Gaussian off the walls: {p:?}"
                    );
                    0
                };
                assert!(
                    normal[axis].abs() > 0.999,
                    "wall Gaussian {i} normal {normal:?}"
                );
                assert!(
                    sc[k] < 0.2 * others,
                    "wall Gaussian {i} is not flat: {sc:?}"
                );
            }
            _ => {}
        }
    }
    assert!(floor > 1000 && walls > 1000);
}

#[test]
fn ball_splats_are_tangent_to_the_sphere() {
    let s = build(9, 50_000);
    let ball = layout_by_name("green ball");
    let c = ball.center.map(f64::from);
    let mut n = 0;
    for (i, &id) in ids(&s).iter().enumerate() {
        if id != ball.id {
            continue;
        }
        n += 1;
        let p = s.means[i].map(f64::from);
        let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
        let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        // Sampled on the surface: every centre sits at the same radius.
        assert!((r - 0.07).abs() < 1e-4, "ball Gaussian at radius {r}");
        let normal = local_axis(s.rotations[i], thin_axis(s.scales[i]));
        let cos = (normal[0] * d[0] + normal[1] * d[1] + normal[2] * d[2]) / r;
        assert!(
            cos.abs() > 0.99,
            "ball Gaussian {i}: normal is {cos} off radial"
        );
    }
    assert!(n > 500);
}

#[test]
fn neighbouring_floor_splats_overlap() {
    let n_total = 100_000;
    let s = build(13, n_total);
    let floor: Vec<usize> = (0..s.len()).filter(|&i| ids(&s)[i] == 0).collect();
    // Mean spacing of samples on the 4 × 4 m floor, against the tangent standard deviations.
    let spacing = (16.0 / floor.len() as f64).sqrt();
    let mean_sigma = floor
        .iter()
        .map(|&i| {
            let mut sc = s.scales[i].map(f64::from);
            sc.sort_by(f64::total_cmp);
            (sc[1] * sc[2]).sqrt()
        })
        .sum::<f64>()
        / floor.len() as f64;
    let ratio = mean_sigma / spacing;
    assert!(
        (0.6..=1.0).contains(&ratio),
        "floor splat sigma is {ratio} x the spacing"
    );
}

#[test]
fn object_colours_and_materials_match_their_names() {
    let s = build(17, 50_000);
    let mean_colour = |name: &str| {
        let id = layout_by_name(name).id;
        let idx: Vec<usize> = (0..s.len()).filter(|&i| ids(&s)[i] == id).collect();
        let mut c = [0.0f32; 3];
        for &i in &idx {
            let b = s.base_color(i);
            for k in 0..3 {
                c[k] += b[k] / idx.len() as f32;
            }
        }
        let o = idx.iter().map(|&i| s.opacities[i]).sum::<f32>() / idx.len() as f32;
        (c, o)
    };
    let ([r, g, b], _) = mean_colour("red mug");
    assert!(r > g + 0.2 && r > b + 0.2, "red mug is {r} {g} {b}");
    let ([r, g, b], _) = mean_colour("green ball");
    assert!(g > r + 0.2 && g > b + 0.2, "green ball is {r} {g} {b}");
    let ([r, g, b], _) = mean_colour("blue box");
    assert!(b > r + 0.2 && b > g + 0.2, "blue box is {r} {g} {b}");
    let ([r, g, b], _) = mean_colour("yellow cone");
    assert!(r > b + 0.3 && g > b + 0.3, "yellow cone is {r} {g} {b}");
    // The glass of water is see-through; the mug is solid.
    let (_, glass) = mean_colour("glass of water");
    let (_, mug) = mean_colour("red mug");
    assert!(glass < 0.5, "glass mean opacity {glass}");
    assert!(mug > 0.7, "mug mean opacity {mug}");
}

/// Parameter interval in which the ray `o + t·d` is inside the box, if any (slab method).
fn ray_box(o: [f64; 3], d: [f64; 3], min: [f32; 3], max: [f32; 3]) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..3 {
        let (a, b) = (
            (f64::from(min[k]) - o[k]) / d[k],
            (f64::from(max[k]) - o[k]) / d[k],
        );
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    (t0 <= t1).then_some((t0, t1))
}

#[test]
fn the_blue_box_hides_the_glass_from_the_documented_viewpoint() {
    let eye = DEMO_VIEWPOINT.map(f64::from);
    let glass = layout_by_name("glass of water");
    let blocker = layout_by_name("blue box");
    let target = glass.center.map(f64::from);
    let d = [target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]];
    // On the segment from the eye to the glass's centre (t in (0, 1)), the ray crosses the
    // box before it reaches the glass's own box.
    let (b0, b1) = ray_box(eye, d, blocker.min(), blocker.max()).expect("ray misses the box");
    let (g0, _) = ray_box(eye, d, glass.min(), glass.max()).expect("ray misses the glass");
    assert!(b0 > 0.0 && b1 < g0, "box [{b0}, {b1}], glass from {g0}");
    // And in the actual scene, box Gaussians sit on that segment (within 1 cm of it).
    let s = build(7, 50_000);
    let len2 = d.iter().map(|v| v * v).sum::<f64>();
    let hits = (0..s.len())
        .filter(|&i| ids(&s)[i] == blocker.id)
        .filter(|&i| {
            let p = s.means[i].map(f64::from);
            let w = [p[0] - eye[0], p[1] - eye[1], p[2] - eye[2]];
            let t = (w[0] * d[0] + w[1] * d[1] + w[2] * d[2]) / len2;
            let q = [w[0] - t * d[0], w[1] - t * d[1], w[2] - t * d[2]];
            t > 0.0 && t < 1.0 && q.iter().map(|v| v * v).sum::<f64>().sqrt() < 0.01
        })
        .count();
    assert!(
        hits > 0,
        "no blue box Gaussian near the line of sight to the glass"
    );
}
