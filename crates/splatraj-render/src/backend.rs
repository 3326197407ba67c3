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

/// What to install for wgpu to find a GPU.
const DRIVER_ADVICE: &str = "Install the GPU's Vulkan driver (NVIDIA: the driver's Vulkan ICD; \
     AMD and Intel: mesa-vulkan-drivers)";

/// A backend was asked for that this build or this machine cannot give.
#[derive(Debug, Clone, thiserror::Error)]
pub enum BackendUnavailable {
    /// The backend is not compiled into this build.
    #[error(
        "backend '{requested}' is not compiled into this build (available: {available}); rebuild with `--features {feature}`"
    )]
    NotCompiled {
        /// The backend asked for.
        requested: BackendKind,
        /// The cargo feature that provides it.
        feature: &'static str,
        /// The backends this build has.
        available: String,
    },
    /// The device has no 64-bit floats (wgpu on Metal, OpenGL and some GPUs) and f64 was asked
    /// for.
    #[error(
        "backend 'wgpu' runs on {hardware}, which has no 64-bit floats (its GPU or graphics API \
         lacks them: Metal, OpenGL and some GPUs): use precision = \"f32\" (`--dtype f32`), or \
         backend = \"flex\" for f64"
    )]
    NoFloat64 {
        /// What the device computes on ([`Hardware`]'s words).
        hardware: String,
    },
    /// wgpu found no adapter it could start (no Vulkan, Metal or DX12 driver, or none of the
    /// kind `CUBECL_WGPU_DEFAULT_DEVICE` asks for).
    #[error(
        "backend 'wgpu' could not start a device: {reason}. {DRIVER_ADVICE}, check CUBECL_WGPU_DEFAULT_DEVICE if it is set, or run with backend = \"flex\""
    )]
    NoDevice {
        /// What wgpu said.
        reason: String,
    },
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
                let device = wgpu_device()?;
                crate::counters::watch_launches();
                Ok(device)
            }
            #[allow(unreachable_patterns)] // reachable when a feature is off
            other => Err(other.not_compiled()),
        }
    }

    /// A device of this backend that holds tensors of `dtype`: [`Self::device`], and an error
    /// where f64 is asked of a device without 64-bit floats. burn would find that out only
    /// when a kernel failed to compile deep inside a pass (naga: "Using `f64` values requires
    /// the FLOAT64 capability"), and the pass would end in a panic.
    pub fn device_for(self, dtype: DType) -> Result<Device, BackendUnavailable> {
        let device = self.device()?;
        if dtype == DType::F64 && !has_f64(&device) {
            return Err(BackendUnavailable::NoFloat64 {
                hardware: Hardware::of(&device).to_string(),
            });
        }
        Ok(device)
    }

    /// The error for asking this build for this backend when it lacks it.
    pub(crate) fn not_compiled(self) -> BackendUnavailable {
        BackendUnavailable::NotCompiled {
            requested: self,
            feature: self.feature(),
            available: Self::compiled()
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(", "),
        }
    }
}

/// wgpu's default device, started once a process with burn's fallible `Device::wgpu_options()
/// .init()`: burn's lazy `Device::wgpu` starts it on a thread of its own at the first op and
/// panics there when no adapter answers (a machine without a GPU driver, a
/// `CUBECL_WGPU_DEFAULT_DEVICE` naming no adapter), which ended a command as an internal error.
#[cfg(feature = "wgpu")]
fn wgpu_device() -> Result<Device, BackendUnavailable> {
    static STARTED: std::sync::OnceLock<Result<Device, String>> = std::sync::OnceLock::new();
    STARTED
        .get_or_init(|| Device::wgpu_options().init().map_err(|e| e.to_string()))
        .clone()
        .map_err(|reason| BackendUnavailable::NoDevice { reason })
}

/// The CubeCL device inside `device` where it is a wgpu device; None on the host backends. The
/// one place that unwraps burn's type-erased device: what a device can hold and do (its largest
/// buffer, workgroup memory, float types, name) is a property of its CubeCL client.
#[cfg(feature = "wgpu")]
pub(crate) fn cube_device(device: &Device) -> Option<burn_cubecl::CubeDevice> {
    match device.as_dispatch().clone().inner() {
        burn_dispatch::DispatchDevice::Cube(cube) => Some(cube),
        #[allow(unreachable_patterns)] // reachable when a host backend is compiled in
        _ => None,
    }
}

/// Whether `device` computes in 64-bit floats: the host backends always; a wgpu device where its
/// adapter and graphics API have them (CubeCL registers the types the adapter offers).
pub fn has_f64(device: &Device) -> bool {
    #[cfg(feature = "wgpu")]
    if let Some(cube) = cube_device(device) {
        use burn_cubecl::cubecl::ir::{ElemType, FloatKind};
        return cube
            .client()
            .properties()
            .supports_type(ElemType::Float(FloatKind::F64));
    }
    #[cfg(not(feature = "wgpu"))]
    let _ = device;
    true
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
        if cube_device(device).is_some() {
            return Execution::Kernels;
        }
        #[cfg(not(feature = "wgpu"))]
        let _ = device;
        Execution::Host
    }
}

/// What a device computes on, as runs and benchmarks report it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Hardware {
    /// The host's cores (flex, ndarray): rayon's threads.
    Cpu {
        /// Threads of rayon's global pool.
        threads: usize,
    },
    /// A GPU, by the name its driver gives (`NVIDIA H200`).
    Gpu {
        /// The adapter's name.
        name: String,
    },
    /// wgpu on a CPU adapter (Mesa's lavapipe, "llvmpipe …"): no GPU driver was found, so every
    /// kernel runs emulated on the host, many times slower than flex.
    EmulatedGpu {
        /// The adapter's name.
        name: String,
    },
}

impl Hardware {
    /// What `device` computes on.
    pub fn of(device: &Device) -> Hardware {
        #[cfg(feature = "wgpu")]
        if let Some(cube) = cube_device(device) {
            let identity = cube.client().properties().identity.clone();
            // CubeCL leaves `physical` empty for a CPU adapter (a software rasterizer) only.
            return match identity.physical {
                Some(_) => Hardware::Gpu {
                    name: identity.name,
                },
                None => Hardware::EmulatedGpu {
                    name: identity.name,
                },
            };
        }
        #[cfg(not(feature = "wgpu"))]
        let _ = device;
        Hardware::Cpu {
            threads: rayon::current_num_threads(),
        }
    }

    /// Why a run on this hardware will be slow and what to do, where it will be.
    pub fn warning(&self) -> Option<String> {
        match self {
            Hardware::EmulatedGpu { name } => Some(format!(
                "backend \"wgpu\" found no GPU driver and runs on {name}, a GPU emulated on the \
                 CPU, many times slower than backend \"flex\". {DRIVER_ADVICE}, or pick a GPU \
                 `splatraj devices` lists with CUBECL_WGPU_DEFAULT_DEVICE"
            )),
            Hardware::Cpu { .. } | Hardware::Gpu { .. } => None,
        }
    }
}

/// The words `scripts/gpu_check_table.py` and the device pack's `run.sh` read: `GPU …` for a
/// GPU, `emulated GPU …` for a CPU adapter.
impl fmt::Display for Hardware {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Hardware::Cpu { threads } => write!(f, "CPU ({threads} threads)"),
            Hardware::Gpu { name } => write!(f, "GPU {name}"),
            Hardware::EmulatedGpu { name } => write!(f, "emulated GPU {name}"),
        }
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

#[cfg(test)]
mod tests {
    use super::Hardware;

    /// The device pack's `run.sh` measures only where the words start with `GPU `, and
    /// `gpu_check_table.py` warns where they start with `emulated GPU`: a rename here must
    /// change them too.
    #[test]
    fn hardware_words_are_the_ones_the_scripts_read() {
        let gpu = Hardware::Gpu {
            name: "NVIDIA H200".into(),
        };
        let emulated = Hardware::EmulatedGpu {
            name: "llvmpipe (LLVM 15.0.6, 256 bits)".into(),
        };
        assert_eq!(gpu.to_string(), "GPU NVIDIA H200");
        assert!(emulated.to_string().starts_with("emulated GPU llvmpipe"));
        assert_eq!(
            Hardware::Cpu { threads: 16 }.to_string(),
            "CPU (16 threads)"
        );
        for script in [
            "../../scripts/device_pack.sh",
            "../../scripts/gpu_check_table.py",
        ] {
            let text = std::fs::read_to_string(
                concat!(env!("CARGO_MANIFEST_DIR"), "/").to_owned() + script,
            )
            .unwrap_or_else(|e| panic!("{script}: {e}"));
            let read = if script.ends_with(".sh") {
                "\"GPU \"*)"
            } else {
                "startswith(\"emulated\")"
            };
            assert!(text.contains(read), "{script} no longer reads {read}");
        }
    }
}
