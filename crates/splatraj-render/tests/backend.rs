//! Every compiled backend (flex by default; ndarray and wgpu with their features) runs the
//! compositing core and its autodiff, checked against the closed form in f64 on the host.

use burn::tensor::{Tensor, TensorData};
use splatraj_render::backend::{BackendKind, Precision};
use splatraj_render::compositing::exclusive_transmittance;

const ALPHA: [[f64; 4]; 2] = [[0.5, 0.99, 0.2, 0.0], [0.1, 0.3, 0.7, 0.99]];

/// T_i = Π_{j<i}(1 − α_j) and d(Σ_i T_i)/dα_k = −Σ_{i>k} T_i/(1 − α_k), by hand.
fn closed_form() -> (Vec<f64>, Vec<f64>) {
    let mut t = Vec::new();
    let mut grad = Vec::new();
    for row in ALPHA {
        let ts: Vec<f64> = (0..4)
            .map(|i| row[..i].iter().map(|a| 1.0 - a).product())
            .collect();
        for k in 0..4 {
            grad.push(-ts[k + 1..].iter().sum::<f64>() / (1.0 - row[k]));
        }
        t.extend(ts);
    }
    (t, grad)
}

fn check(backend: BackendKind, precision: Precision, tolerance: f64) {
    let device = backend.device().expect("compiled backend").autodiff();
    let data = TensorData::new(ALPHA.concat(), [2, 4]);
    let alpha: Tensor<2> = Tensor::from_data(data, (&device, precision.dtype())).require_grad();
    let transmittance = exclusive_transmittance(alpha.clone());
    let grads = transmittance.clone().sum().backward();
    let got_t: Vec<f64> = transmittance
        .into_data()
        .convert::<f64>()
        .try_to_vec::<f64>()
        .unwrap();
    let got_grad: Vec<f64> = alpha
        .grad(&grads)
        .expect("gradient")
        .into_data()
        .convert::<f64>()
        .try_to_vec::<f64>()
        .unwrap();
    let (want_t, want_grad) = closed_form();
    for (k, (got, want)) in got_t
        .iter()
        .zip(&want_t)
        .chain(got_grad.iter().zip(&want_grad))
        .enumerate()
    {
        assert!(
            (got - want).abs() <= tolerance * (1.0 + want.abs()),
            "{backend} {precision:?} value {k}: got {got}, want {want}"
        );
    }
}

#[test]
fn compiled_backends_composite_and_differentiate() {
    let compiled = BackendKind::compiled();
    assert!(
        !compiled.is_empty(),
        "a build without any backend cannot render"
    );
    for backend in compiled {
        check(backend, Precision::F32, 1e-5);
        if backend != BackendKind::Wgpu {
            check(backend, Precision::F64, 1e-12);
        }
    }
}

#[test]
fn missing_backend_names_its_feature() {
    for backend in BackendKind::ALL.into_iter().filter(|b| !b.is_compiled()) {
        let message = backend.device().unwrap_err().to_string();
        assert!(
            message.contains(&format!("--features {}", backend.feature())),
            "{message}"
        );
    }
    assert_eq!("cpu".parse::<BackendKind>(), Ok(BackendKind::Flex));
    assert!(
        "cuda"
            .parse::<BackendKind>()
            .unwrap_err()
            .contains("unknown backend 'cuda'")
    );
}
