//! TCE and TRE against hand-computed values, their empty-mask behaviour, and their gradients
//! against central finite differences in f64.

use burn::tensor::{DType, Device, Tensor, TensorData};
use splatraj_traj::costs::{
    HostMoments, MaskMoments, MomentSums, NORM_EPSILON, centroid_offset, coverage, moment_sums,
    tce, tce_of, tce_on_host, tre, tre_of, tre_on_host,
};

/// A mask `[B, H, W]` from host values in `dtype` on `device`.
fn mask(values: Vec<f64>, shape: [usize; 3], device: &Device, dtype: DType) -> Tensor<3> {
    Tensor::from_data(TensorData::new(values, shape), (device, dtype))
}

fn host<const D: usize>(t: Tensor<D>) -> Vec<f64> {
    t.into_data().convert::<f64>().try_to_vec::<f64>().unwrap()
}

/// Pixels (column i, row j) of an H×W image for which `inside(i, j)` holds set to 1.
fn pattern(height: usize, width: usize, inside: impl Fn(usize, usize) -> bool) -> Vec<f64> {
    let mut out = Vec::with_capacity(height * width);
    for j in 0..height {
        for i in 0..width {
            out.push(if inside(i, j) { 1.0 } else { 0.0 });
        }
    }
    out
}

/// A disc of radius 15 px centred on a 64×64 image (symmetric under both mirrors).
fn centred_disc() -> Vec<f64> {
    pattern(64, 64, |i, j| {
        let (x, y) = (i as f64 + 0.5 - 32.0, j as f64 + 0.5 - 32.0);
        x * x + y * y <= 15.0 * 15.0
    })
}

/// Columns 4..12 and rows 2..8 of a 40×20 image: centroid (8, 5) px, i.e. (0.2, 0.25) of the
/// frame, so TCE = ‖(0.2 − 0.5, 0.25 − 0.5)‖ = √0.1525, and it covers 48/800 = 6 %.
fn off_centre_rectangle() -> Vec<f64> {
    pattern(20, 40, |i, j| (4..12).contains(&i) && (2..8).contains(&j))
}

#[test]
fn centred_disc_has_zero_tce_in_both_precisions() {
    let device = Device::flex();
    for dtype in [DType::F64, DType::F32] {
        let value = host(tce(mask(centred_disc(), [1, 64, 64], &device, dtype)));
        assert_eq!(value, vec![0.0], "{dtype:?}");
    }
}

#[test]
fn off_centre_rectangle_has_closed_form_tce() {
    let device = Device::flex();
    // Batch of two: the rectangle and its mirror image in x (centroid (32, 5) px).
    let rect = off_centre_rectangle();
    let mirrored: Vec<f64> = (0..20)
        .flat_map(|j| (0..40).rev().map(move |i| (j, i)))
        .map(|(j, i)| rect[j * 40 + i])
        .collect();
    let batch = [rect, mirrored].concat();
    for (dtype, tolerance) in [(DType::F64, 2.0 * NORM_EPSILON), (DType::F32, 2e-6)] {
        let m = mask(batch.clone(), [2, 20, 40], &device, dtype);
        let offset = host(centroid_offset(m.clone()));
        let want_offset = [-0.3, -0.25, 0.3, -0.25];
        for (got, want) in offset.iter().zip(want_offset) {
            assert!((got - want).abs() < 1e-6, "{dtype:?}: offset {offset:?}");
        }
        let value = host(tce(m));
        let want = 0.1525f64.sqrt();
        for v in &value {
            assert!(
                (v - want).abs() <= tolerance,
                "{dtype:?}: {value:?} vs {want}"
            );
        }
    }
}

#[test]
fn known_area_has_known_tre() {
    let device = Device::flex();
    let rect = off_centre_rectangle(); // 48 of 800 pixels
    // Second sample: the same rectangle at half intensity plus one full pixel: 25/800.
    let mut half: Vec<f64> = rect.iter().map(|v| 0.5 * v).collect();
    half[799] = 1.0;
    let m = mask([rect, half].concat(), [2, 20, 40], &device, DType::F64);
    let cov = host(coverage(m.clone()));
    assert!((cov[0] - 0.06).abs() < 1e-15 && (cov[1] - 25.0 / 800.0).abs() < 1e-15);
    let value = host(tre(m.clone(), 0.15));
    assert!((value[0] - 0.09).abs() < 1e-15, "{value:?}");
    assert!(
        (value[1] - (0.15 - 25.0 / 800.0)).abs() < 1e-15,
        "{value:?}"
    );
    // Above the target the error is the excess.
    let value = host(tre(m, 0.01));
    assert!((value[0] - 0.05).abs() < 1e-15, "{value:?}");
}

#[test]
fn empty_mask_is_finite_with_zero_tce_gradient() {
    let device = Device::flex().autodiff();
    for dtype in [DType::F64, DType::F32] {
        let (h, w) = (12, 20);
        let x = mask(vec![0.0; 2 * h * w], [2, h, w], &device, dtype).require_grad();
        let cost = tce(x.clone());
        let grads = cost.clone().sum().backward();
        assert_eq!(
            host(cost),
            vec![0.0, 0.0],
            "{dtype:?}: centroid at the centre"
        );
        let grad = host(x.grad(&grads).expect("gradient exists"));
        assert!(grad.iter().all(|&g| g == 0.0), "{dtype:?}: {grad:?}");

        let x = mask(vec![0.0; 2 * h * w], [2, h, w], &device, dtype).require_grad();
        let cost = tre(x.clone(), 0.15);
        let grads = cost.clone().sum().backward();
        let value = host(cost);
        assert!(value.iter().all(|v| (v - 0.15).abs() < 1e-7), "{value:?}");
        // The exact derivative −1/(W·H): finite, and it cannot move a pose (see tre docs).
        let grad = host(x.grad(&grads).expect("gradient exists"));
        let want = -1.0 / (h * w) as f64;
        assert!(
            grad.iter()
                .all(|g| g.is_finite() && (g - want).abs() < 1e-7),
            "{dtype:?}: {grad:?}"
        );
    }
}

/// Small deterministic generator (xorshift).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn gradients_match_finite_differences_in_f64() {
    let (b, h, w) = (3, 5, 7);
    let mut rng = Rng(0x5eed);
    let mut values = Vec::new();
    // Sample 0: fractional mask weighted to the left; sample 1: sparse and off-centre;
    // sample 2: total mass 3e-4, below the mass floor (the floored branch).
    for j in 0..h {
        for i in 0..w {
            values.push(rng.next() * (1.0 - i as f64 / w as f64) * (0.3 + j as f64 / h as f64));
        }
    }
    for _ in 0..h * w {
        let v = rng.next();
        values.push(if v > 0.6 { v } else { 0.0 });
    }
    for _ in 0..h * w {
        values.push(rng.next() * 3e-4 / (0.5 * (h * w) as f64));
    }
    let weights = [(1.0, 0.0), (0.0, 1.0), (0.7, 1.3)];
    let target = 0.4;
    let loss = |x: Tensor<3>, (a, c): (f64, f64)| -> Tensor<1> {
        (tce(x.clone()).mul_scalar(a) + tre(x, target).mul_scalar(c)).sum()
    };
    let plain = Device::flex();
    let ad = Device::flex().autodiff();
    for weight in weights {
        let x = mask(values.clone(), [b, h, w], &ad, DType::F64).require_grad();
        let grads = loss(x.clone(), weight).backward();
        let grad = host(x.grad(&grads).unwrap());
        let value = |v: Vec<f64>| -> f64 {
            loss(mask(v, [b, h, w], &plain, DType::F64), weight).into_scalar::<f64>()
        };
        let mut worst = 0.0f64;
        for k in 0..values.len() {
            // The floored sample is ~300× more sensitive (1/floor): a smaller step keeps the
            // O(h²) truncation error of central differences below the tolerance.
            let step = if k >= 2 * h * w { 1e-10 } else { 1e-7 };
            let (mut plus, mut minus) = (values.clone(), values.clone());
            plus[k] += step;
            minus[k] -= step;
            let fd = (value(plus) - value(minus)) / (2.0 * step);
            let error = (grad[k] - fd).abs() / fd.abs().max(1.0);
            worst = worst.max(error);
            assert!(
                error < 1e-6,
                "weights {weight:?}, pixel {k}: autodiff {} vs finite differences {fd}",
                grad[k]
            );
        }
        assert!(grad.iter().any(|g| g.abs() > 1e-3), "{weight:?}: trivial");
        assert!(worst.is_finite());
    }
}

/// The moments of random non-square mask batches, summed both ways (the host's two matrix
/// products and the GPU's three reductions), equal a brute-force f64 double loop over the
/// pixels, in both precisions; an all-ones 1280×720 frame keeps its mass
/// (921 600 pixels) in f32. Three sizes, two sharing a height and two a width, one after the
/// other: the pixel centres of a size are kept on the device and must not be taken for
/// another's.
#[test]
fn mask_moments_match_brute_force_sums() {
    let device = Device::flex();
    let ways = [MomentSums::Products, MomentSums::Reductions];
    let mut rng = Rng(0xa11ce);
    for (b, h, w, dtype, tolerance, sums) in [(2, 91, 160), (1, 91, 64), (3, 40, 160)]
        .into_iter()
        .flat_map(|size| [(size, DType::F64, 1e-12), (size, DType::F32, 1e-5)])
        .flat_map(|((b, h, w), d, t)| ways.map(|s| (b, h, w, d, t, s)))
    {
        let values: Vec<f64> = (0..b * h * w).map(|_| rng.next()).collect();
        let moments = MaskMoments::summed(mask(values.clone(), [b, h, w], &device, dtype), sums);
        let (mass, first_x, first_y) = (
            host(moments.mass()),
            host(moments.first_x()),
            host(moments.first_y()),
        );
        for s in 0..b {
            let (mut m, mut mx, mut my) = (0.0, 0.0, 0.0);
            for j in 0..h {
                for i in 0..w {
                    let v = values[(s * h + j) * w + i];
                    m += v;
                    mx += v * ((i as f64 + 0.5) / w as f64 - 0.5);
                    my += v * ((j as f64 + 0.5) / h as f64 - 0.5);
                }
            }
            let close = |got: f64, want: f64| (got - want).abs() <= tolerance * m;
            assert!(
                close(mass[s], m),
                "{dtype:?} {sums:?} mass {} vs {m}",
                mass[s]
            );
            assert!(
                close(first_x[s], mx),
                "{dtype:?} {sums:?} Σm·x {} vs {mx}",
                first_x[s]
            );
            assert!(
                close(first_y[s], my),
                "{dtype:?} {sums:?} Σm·y {} vs {my}",
                first_y[s]
            );
        }
    }
    for sums in ways {
        let ones = Tensor::<3>::ones([1, 720, 1280], (&device, DType::F32));
        let moments = MaskMoments::summed(ones, sums);
        assert_eq!(host(moments.mass()), vec![921_600.0], "{sums:?}");
        assert_eq!(host(moments.coverage()), vec![1.0], "{sums:?}");
    }
}

/// TCE, TRE and their gradients in the mask (f64) are the same whichever way the moments are
/// summed: the GPU's reductions against the host's products, on a random mask batch, after the
/// same size's moments were summed without autodiff.
#[test]
fn both_moment_sums_give_the_same_costs_and_gradients() {
    let device = Device::flex().autodiff();
    let (b, h, w) = (3, 27, 48);
    let mut rng = Rng(0x5eed);
    let values: Vec<f64> = (0..b * h * w).map(|_| rng.next()).collect();
    // The moments' constants of this size made first without autodiff, as a run's metrics may
    // make them before its optimisation: the gradient must not take them for its own (burn's
    // device equality ignores autodiff).
    let plain = mask(values.clone(), [b, h, w], &Device::flex(), DType::F64);
    for sums in [MomentSums::Products, MomentSums::Reductions] {
        host(MaskMoments::summed(plain.clone(), sums).mass());
    }
    let run = |sums: MomentSums| {
        let x = mask(values.clone(), [b, h, w], &device, DType::F64).require_grad();
        let moments = MaskMoments::summed(x.clone(), sums);
        let costs = tce_of(&moments) + tre_of(&moments, 0.2);
        let grads = costs.clone().sum().backward();
        (
            host(costs.without_autodiff()),
            host(x.grad(&grads).unwrap()),
        )
    };
    let (costs, gradient) = run(MomentSums::Products);
    let (costs_r, gradient_r) = run(MomentSums::Reductions);
    let largest = gradient.iter().fold(0.0f64, |a, g| a.max(g.abs()));
    assert!(largest > 1e-6, "a gradient to compare");
    for (a, r) in costs.iter().zip(&costs_r) {
        assert!((a - r).abs() <= 1e-12, "costs {a} vs {r}");
    }
    for (a, r) in gradient.iter().zip(&gradient_r) {
        assert!((a - r).abs() <= 1e-10 * largest, "gradient {a} vs {r}");
    }
}

/// The figures a frame or a sample reports, made on the host in f64 from the moment sums read
/// back whole, equal the costs' tensor formulas (f64) on the same masks: an off-centre mask, its
/// mirror, an empty mask (TCE 0, TRE the target), a mask lighter than the mass floor, and random
/// masks. The sums' fourth column, Σm·x·y, is the brute-force double loop's. The rectangle's TCE
/// is also its closed form √0.1525.
#[test]
fn host_figures_from_moment_sums_match_the_tensor_costs() {
    let device = Device::flex();
    let (h, w) = (20, 40);
    let rect = off_centre_rectangle();
    let mirrored: Vec<f64> = (0..h)
        .flat_map(|j| (0..w).rev().map(move |i| (j, i)))
        .map(|(j, i)| rect[j * w + i])
        .collect();
    let mut rng = Rng(0xf00d);
    let random: Vec<f64> = (0..3 * h * w).map(|_| rng.next()).collect();
    let mut light = vec![0.0; h * w];
    light[w + 3] = 4e-4; // below MASS_FLOOR, off centre
    let values = [rect, mirrored, vec![0.0; h * w], light, random].concat();
    let b = values.len() / (h * w);
    let target = 0.15;
    let masks = mask(values.clone(), [b, h, w], &device, DType::F64);
    let sums = host(moment_sums(masks.clone().unsqueeze_dim(3), 0));
    assert_eq!(sums.len(), 4 * b);
    // The same mask as the middle channel of three, between channels of other values.
    let junk: Vec<f64> = (0..values.len()).map(|_| 1.0 + rng.next()).collect();
    let interleaved: Vec<f64> = (0..values.len())
        .flat_map(|k| [junk[k], values[k], -junk[k]])
        .collect();
    let images = Tensor::<4>::from_data(
        TensorData::new(interleaved, [b, h, w, 3]),
        (&device, DType::F64),
    );
    let of_channel = host(moment_sums(images.clone(), 1));
    for (k, (got, want)) in of_channel.iter().zip(&sums).enumerate() {
        assert!(
            (got - want).abs() <= 1e-12,
            "sum {k}: channel 1 of 3 {got} vs the mask's {want}"
        );
    }
    // Its neighbours through the same layout after it (the same shape of constants, other
    // values: each channel's selection must be its own), against each alone.
    for (channel, sign) in [(0, 1.0), (2, -1.0)] {
        let alone: Vec<f64> = junk.iter().map(|v| sign * v).collect();
        let alone = host(moment_sums(
            mask(alone, [b, h, w], &device, DType::F64).unsqueeze_dim(3),
            0,
        ));
        let of_channel = host(moment_sums(images.clone(), channel));
        for (k, (got, want)) in of_channel.iter().zip(&alone).enumerate() {
            assert!(
                (got - want).abs() <= 1e-9,
                "sum {k}: channel {channel} of 3 {got} vs alone {want}"
            );
        }
    }
    let figures = HostMoments::from_sums(&sums, h * w);
    let moments = MaskMoments::summed(masks, MomentSums::Products);
    let (tces, tres, coverages) = (
        host(tce_of(&moments)),
        host(tre_of(&moments, target)),
        host(moments.coverage()),
    );
    for (s, m) in figures.iter().enumerate() {
        let mut mxy = 0.0;
        for j in 0..h {
            for i in 0..w {
                let (x, y) = (
                    (i as f64 + 0.5) / w as f64 - 0.5,
                    (j as f64 + 0.5) / h as f64 - 0.5,
                );
                mxy += values[(s * h + j) * w + i] * x * y;
            }
        }
        assert!((sums[4 * s + 3] - mxy).abs() <= 1e-12, "sample {s}: Σm·x·y");
        let close = |got: f64, want: f64| (got - want).abs() <= 1e-12 * want.abs().max(1.0);
        assert!(
            close(tce_on_host(m), tces[s]),
            "sample {s}: TCE {} vs {}",
            tce_on_host(m),
            tces[s]
        );
        assert!(close(tre_on_host(m, target), tres[s]), "sample {s}: TRE");
        assert!(close(m.coverage(), coverages[s]), "sample {s}: coverage");
    }
    for rectangle in &figures[..2] {
        assert!((tce_on_host(rectangle) - 0.1525f64.sqrt()).abs() <= 2.0 * NORM_EPSILON);
    }
    assert_eq!(tce_on_host(&figures[2]), 0.0, "an empty mask is centred");
    assert_eq!(tre_on_host(&figures[2], target), target);
    assert!(tce_on_host(&figures[3]) > 0.0 && tce_on_host(&figures[3]) < 0.5);
}
