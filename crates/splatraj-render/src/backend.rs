//! Which burn backend runs the tensors, chosen at run time among those compiled in.

use std::fmt;
use std::str::FromStr;

use burn::tensor::{DType, Device};
use serde::{Deserialize, Serialize};

/// A burn backend splatraj can run on. Which ones exist depends on the cargo features.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BackendKind {
    /// burn's pure-Rust CPU backend (the default; also spelled `cpu`).
    #[serde(alias = "cpu")]
    Flex,
    /// burn's ndarray CPU backend (deprecated upstream; cargo feature `ndarray`).
    Ndarray,
    /// GPU through wgpu (Vulkan, Metal, DX12; cargo feature `wgpu`).
    Wgpu,
}

/// Floating-point precision of a render.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Precision {
    /// 32-bit floats: the normal choice.
    #[default]
    F32,
    /// 64-bit floats: for gradient checks on the CPU backends.
    F64,
}

impl Precision {
    /// The burn dtype of this precision.
    pub fn dtype(self) -> DType {
        match self {
            Precision::F32 => DType::F32,
            Precision::F64 => DType::F64,
        }
    }
}

/// A backend was asked for that this build does not have.
#[derive(Debug, Clone, thiserror::Error)]
#[error(
    "backend '{requested}' is not compiled into this build (available: {available}); rebuild with `--features {feature}`"
)]
pub struct BackendUnavailable {
    /// The backend asked for.
    pub requested: BackendKind,
    /// The cargo feature that provides it.
    pub feature: &'static str,
    /// The backends this build has.
    pub available: String,
}

impl BackendKind {
    /// Every backend, compiled in or not.
    pub const ALL: [BackendKind; 3] = [BackendKind::Flex, BackendKind::Ndarray, BackendKind::Wgpu];

    /// The cargo feature that compiles this backend in.
    pub fn feature(self) -> &'static str {
        match self {
            BackendKind::Flex => "flex",
            BackendKind::Ndarray => "ndarray",
            BackendKind::Wgpu => "wgpu",
        }
    }

    /// Whether this build has the backend.
    pub fn is_compiled(self) -> bool {
        match self {
            BackendKind::Flex => cfg!(feature = "flex"),
            BackendKind::Ndarray => cfg!(feature = "ndarray"),
            BackendKind::Wgpu => cfg!(feature = "wgpu"),
        }
    }

    /// The backends this build has.
    pub fn compiled() -> Vec<BackendKind> {
        Self::ALL.into_iter().filter(|b| b.is_compiled()).collect()
    }

    /// A device of this backend (without autodiff; call `.autodiff()` for gradients).
    pub fn device(self) -> Result<Device, BackendUnavailable> {
        match self {
            #[cfg(feature = "flex")]
            BackendKind::Flex => Ok(Device::flex()),
            #[cfg(feature = "ndarray")]
            #[allow(deprecated)]
            // kept as an option for users comparing against older burn
            BackendKind::Ndarray => Ok(Device::ndarray()),
            #[cfg(feature = "wgpu")]
            BackendKind::Wgpu => {
                crate::counters::watch_launches();
                Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice))
            }
            #[allow(unreachable_patterns)] // reachable when a feature is off
            other => Err(BackendUnavailable {
                requested: other,
                feature: other.feature(),
                available: Self::compiled()
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(", "),
            }),
        }
    }
}

/// How `device` runs tensor ops: as kernel launches on a GPU (each op a launch, queued and
/// fused by burn-fusion) or on the host. Code whose best formulation differs between the two
/// asks here (e.g. `splatraj_traj::costs::MaskMoments`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Execution {
    /// On the host (flex, ndarray): an op costs its arithmetic.
    Host,
    /// Kernel launches on a GPU (wgpu): an op costs a launch unless fusion merges it.
    Kernels,
}

impl Execution {
    /// How `device` runs ops.
    pub fn of(device: &Device) -> Self {
        #[cfg(feature = "wgpu")]
        if let burn_dispatch::DispatchDevice::Cube(_) = device.as_dispatch().clone().inner() {
            return Execution::Kernels;
        }
        #[cfg(not(feature = "wgpu"))]
        let _ = device;
        Execution::Host
    }
}

impl fmt::Display for BackendKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.feature())
    }
}

impl FromStr for BackendKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "flex" | "cpu" => Ok(BackendKind::Flex),
            "ndarray" => Ok(BackendKind::Ndarray),
            "wgpu" | "gpu" => Ok(BackendKind::Wgpu),
            _ => Err(format!(
                "unknown backend '{s}' (expected flex, cpu, ndarray or wgpu)"
            )),
        }
    }
}
