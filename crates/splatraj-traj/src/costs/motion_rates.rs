//! The motion limits' charges of one stretch of path, on the host in f64, with their gradient
//! in the stretch's poses written out by hand ([`super::motion`] gives the formulas; this file
//! follows them term by term, with the tensor formulation's conventions at the kinks: a hinge
//! max(0, z) and a floor pass the gradient where the value lies on their bound too, as burn's
//! `clamp_min` does). `tests/motion_host.rs` holds it to the tensor formulation in f64.

use splatraj_render::rodrigues::Rotation;

/// The limits a stretch is charged against, in per-second units (angles in radians).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotionLimits {
    /// Largest speed.
    pub speed: Option<f64>,
    /// Largest acceleration.
    pub acceleration: Option<f64>,
    /// Largest turning rate, radians per second.
    pub turn: Option<f64>,
    /// Largest orbit rate about the pivot, radians per second.
    pub orbit: Option<f64>,
    /// Weight of the even-speed term (0: off).
    pub even_speed: f64,
}

/// One stretch of path as the charges read it.
#[derive(Debug, Clone, Copy)]
pub struct Stretch<'a> {
    /// Its poses Φ, evenly spaced in time.
    pub poses: &'a [[f64; 6]],
    /// Seconds between consecutive poses.
    pub dt: f64,
    /// The point the orbit rate is measured about (its window's object centre).
    pub pivot: [f64; 3],
    /// Squared floor of the distance to the pivot.
    pub floor_sq: f64,
}

/// Fewest poses a stretch needs for its motion to be charged (an acceleration needs three).
pub const MIN_POSES: usize = 3;

/// The stretch's charge, summed term by term.
struct Charges {
    value: f64,
}

impl Charges {
    /// Adds mean_k max(0, x_k/limit² − 1) over the steps' squared rates `x` and returns each
    /// step's d(charge)/d x_k (0 where the hinge is flat).
    fn hinge(&mut self, x: &[f64], limit: f64) -> Vec<f64> {
        let n = x.len() as f64;
        x.iter()
            .map(|&x| {
                let z = x / (limit * limit) - 1.0;
                if z >= 0.0 {
                    self.value += z / n;
                    1.0 / (limit * limit * n)
                } else {
                    0.0
                }
            })
            .collect()
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| a[i] - b[i])
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|i| a[i] * b[i]).sum()
}

fn centre(pose: &[f64; 6]) -> [f64; 3] {
    [pose[3], pose[4], pose[5]]
}

/// Adds `scale`·`v` to the centre part of `gradient`.
fn add_centre(gradient: &mut [f64; 6], v: [f64; 3], scale: f64) {
    for i in 0..3 {
        gradient[3 + i] += scale * v[i];
    }
}

/// The stretch's motion charge (unweighted; 0 below [`MIN_POSES`] poses) and its gradient in
/// each pose.
pub fn stretch_charge(limits: &MotionLimits, stretch: &Stretch) -> (f64, Vec<[f64; 6]>) {
    let poses = stretch.poses;
    let count = poses.len();
    let mut gradient = vec![[0.0; 6]; count];
    if count < MIN_POSES {
        return (0.0, gradient);
    }
    let dt = stretch.dt;
    let mut charges = Charges { value: 0.0 };
    let centres: Vec<[f64; 3]> = poses.iter().map(centre).collect();

    // Speed: v_k = (c_{k+1} − c_k)/Δt, its square x_k; dx_k/dc_{k+1} = 2 (c_{k+1} − c_k)/Δt².
    let steps: Vec<[f64; 3]> = centres.windows(2).map(|w| sub(w[1], w[0])).collect();
    let squared_speed: Vec<f64> = steps.iter().map(|s| dot(*s, *s) / (dt * dt)).collect();
    let mut v_speed = vec![0.0; steps.len()]; // d charge / d x_k
    if let Some(limit) = limits.speed {
        v_speed = charges.hinge(&squared_speed, limit);
    }
    if limits.even_speed > 0.0 {
        // Spread of x about its mean m (floored at 10⁻¹²): mean_k (x_k/m − 1)², through m too.
        let n = squared_speed.len() as f64;
        let mean = squared_speed.iter().sum::<f64>() / n + 1e-12;
        let ratios: Vec<f64> = squared_speed.iter().map(|x| x / mean - 1.0).collect();
        charges.value += limits.even_speed * ratios.iter().map(|r| r * r).sum::<f64>() / n;
        let through_mean: f64 = ratios
            .iter()
            .zip(&squared_speed)
            .map(|(r, x)| -2.0 * r * x / (mean * mean))
            .sum::<f64>()
            / (n * n);
        for (v, r) in v_speed.iter_mut().zip(&ratios) {
            *v += limits.even_speed * (2.0 * r / (mean * n) + through_mean);
        }
    }
    for (k, (step, v)) in steps.iter().zip(&v_speed).enumerate() {
        let scale = 2.0 * v / (dt * dt);
        add_centre(&mut gradient[k + 1], *step, scale);
        add_centre(&mut gradient[k], *step, -scale);
    }

    // Acceleration: a_k = (c_{k+2} − 2c_{k+1} + c_k)/Δt².
    if let Some(limit) = limits.acceleration {
        let second: Vec<[f64; 3]> = steps.windows(2).map(|w| sub(w[1], w[0])).collect();
        let dt4 = dt.powi(4);
        let squared: Vec<f64> = second.iter().map(|a| dot(*a, *a) / dt4).collect();
        for (k, (a, v)) in second
            .iter()
            .zip(charges.hinge(&squared, limit))
            .enumerate()
        {
            let scale = 2.0 * v / dt4;
            add_centre(&mut gradient[k + 2], *a, scale);
            add_centre(&mut gradient[k + 1], *a, -2.0 * scale);
            add_centre(&mut gradient[k], *a, scale);
        }
    }

    // Turning: θ_k²/Δt² = ‖R_{k+1} − R_k‖²_F/(2Δt²), through Rodrigues' derivative.
    if let Some(limit) = limits.turn {
        let rotations: Vec<Rotation> = poses
            .iter()
            .map(|p| Rotation::new([p[0], p[1], p[2]]))
            .collect();
        let turns: Vec<[[f64; 3]; 3]> = rotations
            .windows(2)
            .map(|w| std::array::from_fn(|i| sub(w[1].matrix[i], w[0].matrix[i])))
            .collect();
        let squared: Vec<f64> = turns
            .iter()
            .map(|d| d.iter().map(|row| dot(*row, *row)).sum::<f64>() / (2.0 * dt * dt))
            .collect();
        let mut v_matrices = vec![[[0.0; 3]; 3]; count];
        for (k, (d, v)) in turns.iter().zip(charges.hinge(&squared, limit)).enumerate() {
            let scale = v / (dt * dt); // d(x)/dD = D/Δt²
            for i in 0..3 {
                for j in 0..3 {
                    v_matrices[k + 1][i][j] += scale * d[i][j];
                    v_matrices[k][i][j] -= scale * d[i][j];
                }
            }
        }
        for ((g, r), v) in gradient.iter_mut().zip(&rotations).zip(&v_matrices) {
            let v_omega = r.omega_gradient(v);
            for m in 0..3 {
                g[m] += v_omega[m];
            }
        }
    }

    // Orbit: u_k = (c_k − o)/ℓ_k, ℓ_k = √max(‖c_k − o‖², floor²); φ_k²/Δt² = ‖u_{k+1} − u_k‖²/Δt².
    if let Some(limit) = limits.orbit {
        let offsets: Vec<[f64; 3]> = centres.iter().map(|c| sub(*c, stretch.pivot)).collect();
        let lengths: Vec<f64> = offsets
            .iter()
            .map(|d| dot(*d, *d).max(stretch.floor_sq).sqrt())
            .collect();
        let directions: Vec<[f64; 3]> = offsets
            .iter()
            .zip(&lengths)
            .map(|(d, l)| d.map(|x| x / l))
            .collect();
        let chords: Vec<[f64; 3]> = directions.windows(2).map(|w| sub(w[1], w[0])).collect();
        let squared: Vec<f64> = chords.iter().map(|c| dot(*c, *c) / (dt * dt)).collect();
        let mut v_directions = vec![[0.0; 3]; count];
        for (k, (c, v)) in chords
            .iter()
            .zip(charges.hinge(&squared, limit))
            .enumerate()
        {
            let scale = 2.0 * v / (dt * dt);
            for i in 0..3 {
                v_directions[k + 1][i] += scale * c[i];
                v_directions[k][i] -= scale * c[i];
            }
        }
        for k in 0..count {
            let (d, u, l, v) = (offsets[k], directions[k], lengths[k], v_directions[k]);
            // Above the floor ℓ follows the offset: du/dd = (I − u uᵀ)/ℓ; on it ℓ is a constant.
            let along = if dot(d, d) >= stretch.floor_sq {
                dot(u, v)
            } else {
                0.0
            };
            let v_offset: [f64; 3] = std::array::from_fn(|i| (v[i] - u[i] * along) / l);
            add_centre(&mut gradient[k], v_offset, 1.0);
        }
    }
    (charges.value, gradient)
}
