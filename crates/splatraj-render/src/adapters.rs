//! The adapters wgpu can run on, as `splatraj devices` lists them: each adapter of the graphics
//! API wgpu settles on, the `CUBECL_WGPU_DEFAULT_DEVICE` value that picks it, and which one
//! `backend = "wgpu"` takes.
//!
//! Why: a workstation or a cluster node often has several GPUs (eight H100s, or a discrete GPU
//! beside an integrated one), and a machine whose GPU driver is missing shows only Mesa's CPU
//! emulation. CubeCL picks the adapter: with `CUBECL_WGPU_DEFAULT_DEVICE` unset, the one wgpu
//! offers for high performance; with it set to `DiscreteGpu(n)`, `IntegratedGpu(n)`,
//! `VirtualGpu(n)`, `Other(n)` or `Cpu`, the n-th adapter *of that type* in enumeration order
//! (each type counts from zero on its own; a CPU adapter has no index). Nothing in wgpu or
//! CubeCL prints those values beside the names, so a user could only guess the number.
//!
//! The listing asks wgpu directly (a fresh instance on the API CubeCL's automatic choice
//! settles on: Vulkan where it has a GPU) and starts no device: listing eight GPUs does not
//! allocate on any of them. The numbering ([`selectors`]) and the parsing of the variable
//! ([`Selector::parse`]) follow CubeCL 0.11's rules (`cubecl-wgpu`'s `runtime.rs`), which
//! `tests/backend.rs` checks against the device CubeCL actually starts.

use serde::Serialize;

use crate::backend::BackendUnavailable;

/// The environment variable with which CubeCL picks an adapter.
pub const SELECTOR_VARIABLE: &str = "CUBECL_WGPU_DEFAULT_DEVICE";

/// The type of an adapter, as its driver reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum AdapterKind {
    /// A GPU of its own (NVIDIA, AMD, Intel Arc cards).
    DiscreteGpu,
    /// A GPU sharing the CPU's die and memory.
    IntegratedGpu,
    /// A GPU passed through to a virtual machine.
    VirtualGpu,
    /// A software rasterizer on the CPU (Mesa's lavapipe): a GPU emulated, many times slower
    /// than flex.
    Cpu,
    /// Anything the driver does not classify.
    Other,
}

impl AdapterKind {
    /// The word CubeCL's selector uses for this kind (`DiscreteGpu` in `DiscreteGpu(0)`).
    fn word(self) -> &'static str {
        match self {
            AdapterKind::DiscreteGpu => "DiscreteGpu",
            AdapterKind::IntegratedGpu => "IntegratedGpu",
            AdapterKind::VirtualGpu => "VirtualGpu",
            AdapterKind::Cpu => "Cpu",
            AdapterKind::Other => "Other",
        }
    }

    /// What a listing calls it.
    pub fn describe(self) -> &'static str {
        match self {
            AdapterKind::DiscreteGpu => "discrete GPU",
            AdapterKind::IntegratedGpu => "integrated GPU",
            AdapterKind::VirtualGpu => "virtual GPU",
            AdapterKind::Cpu => "emulated GPU",
            AdapterKind::Other => "other",
        }
    }
}

/// A value of `CUBECL_WGPU_DEFAULT_DEVICE`: an adapter type and, except for `Cpu`, its number
/// among the adapters of that type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Selector {
    /// The adapter type it asks for.
    pub kind: AdapterKind,
    /// Which of the adapters of that type, from 0 (always 0 for `Cpu`).
    pub index: usize,
}

impl Selector {
    /// The selector `value` spells, read as CubeCL reads it (`Cpu`, or a type word followed by
    /// a number in parentheses); None for anything CubeCL refuses.
    pub fn parse(value: &str) -> Option<Selector> {
        if value == "Cpu" {
            return Some(Selector {
                kind: AdapterKind::Cpu,
                index: 0,
            });
        }
        [
            AdapterKind::DiscreteGpu,
            AdapterKind::IntegratedGpu,
            AdapterKind::VirtualGpu,
            AdapterKind::Other,
        ]
        .into_iter()
        .find_map(|kind| {
            let index = value
                .strip_prefix(kind.word())?
                .strip_prefix('(')?
                .strip_suffix(')')?
                .parse()
                .ok()?;
            Some(Selector { kind, index })
        })
    }
}

impl std::fmt::Display for Selector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.kind {
            AdapterKind::Cpu => f.write_str("Cpu"),
            kind => write!(f, "{}({})", kind.word(), self.index),
        }
    }
}

/// The selector of each adapter of a list in enumeration order: each type counts from zero
/// on its own, the CPU adapter is `Cpu` (CubeCL's numbering).
pub fn selectors(kinds: &[AdapterKind]) -> Vec<Selector> {
    let mut counts = std::collections::HashMap::new();
    kinds
        .iter()
        .map(|&kind| {
            let next = counts.entry(kind).or_insert(0);
            let index = if kind == AdapterKind::Cpu { 0 } else { *next };
            *next += 1;
            Selector { kind, index }
        })
        .collect()
}

/// One adapter wgpu offers.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Adapter {
    /// The `CUBECL_WGPU_DEFAULT_DEVICE` value that picks it.
    #[serde(serialize_with = "as_text")]
    pub selector: Selector,
    /// Its type.
    pub kind: AdapterKind,
    /// The name its driver gives (`NVIDIA H200`, `llvmpipe (LLVM 15.0.6, 256 bits)`).
    pub name: String,
    /// The driver's name and version, as it reports them (may be empty).
    pub driver: String,
    /// The PCI bus id, where the driver gives one (tells identical GPUs apart).
    pub pci_bus: String,
}

/// How the adapter `backend = "wgpu"` takes is chosen.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case", tag = "by", content = "value")]
pub enum Choice {
    /// `CUBECL_WGPU_DEFAULT_DEVICE` is unset: wgpu's high-performance adapter.
    Default,
    /// `CUBECL_WGPU_DEFAULT_DEVICE` holds this value.
    Variable(String),
}

/// The adapters of the graphics API wgpu runs on, and which one a run takes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct AdapterListing {
    /// The graphics API (`Vulkan`, `Metal`, `Dx12`, `Gl`).
    pub api: String,
    /// Its adapters, in enumeration order.
    pub adapters: Vec<Adapter>,
    /// How the run's adapter is chosen.
    pub choice: Choice,
    /// The position in `adapters` of the one a run takes; None when the choice matches none
    /// (then `backend = "wgpu"` fails to start, naming the variable).
    pub taken: Option<usize>,
}

impl AdapterListing {
    /// The adapter a run takes.
    pub fn taken(&self) -> Option<&Adapter> {
        self.taken.and_then(|i| self.adapters.get(i))
    }
}

/// Which of `adapters` the value `variable` of `CUBECL_WGPU_DEFAULT_DEVICE` picks: the one whose
/// selector it spells; None when it spells none or none has it.
pub fn picked_by(variable: &str, adapters: &[Adapter]) -> Option<usize> {
    let wanted = Selector::parse(variable)?;
    adapters.iter().position(|a| a.selector == wanted)
}

fn as_text<S: serde::Serializer>(selector: &Selector, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(selector)
}

/// The adapters wgpu can run on and the one a run takes, given the value of
/// `CUBECL_WGPU_DEFAULT_DEVICE` (`variable`; None when unset). Starts no device.
pub fn wgpu_adapters(variable: Option<&str>) -> Result<AdapterListing, BackendUnavailable> {
    #[cfg(feature = "wgpu")]
    return Ok(on_wgpu::list(variable));
    #[cfg(not(feature = "wgpu"))]
    {
        let _ = variable;
        Err(crate::backend::BackendKind::Wgpu.not_compiled())
    }
}

#[cfg(feature = "wgpu")]
mod on_wgpu {
    use burn_wgpu::graphics::{AutoGraphicsApi, GraphicsApi};
    use burn_wgpu::wgpu;

    use super::{Adapter, AdapterKind, AdapterListing, Choice, picked_by, selectors};

    /// Lists the adapters of the API CubeCL's automatic choice settles on.
    pub(super) fn list(variable: Option<&str>) -> AdapterListing {
        // The same API a default device comes up on (CubeCL: the first of Vulkan, DX12, GL with
        // a GPU, else the first with any adapter).
        let api = AutoGraphicsApi::backend();
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: api.into(),
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let infos: Vec<wgpu::AdapterInfo> =
            futures_lite::future::block_on(instance.enumerate_adapters(api.into()))
                .iter()
                .map(wgpu::Adapter::get_info)
                .collect();
        let kinds: Vec<AdapterKind> = infos.iter().map(|i| kind(i.device_type)).collect();
        let adapters: Vec<Adapter> = infos
            .iter()
            .zip(selectors(&kinds))
            .map(|(info, selector)| Adapter {
                selector,
                kind: selector.kind,
                name: info.name.clone(),
                driver: [info.driver.as_str(), info.driver_info.as_str()]
                    .into_iter()
                    .filter(|s| !s.is_empty())
                    .collect::<Vec<_>>()
                    .join(" "),
                pci_bus: info.device_pci_bus_id.clone(),
            })
            .collect();
        let (choice, taken) = match variable {
            Some(value) => (
                Choice::Variable(value.to_string()),
                picked_by(value, &adapters),
            ),
            // CubeCL's default device asks wgpu for its high-performance adapter.
            None => {
                let preferred = futures_lite::future::block_on(instance.request_adapter(
                    &wgpu::RequestAdapterOptions {
                        power_preference: wgpu::PowerPreference::HighPerformance,
                        ..wgpu::RequestAdapterOptions::default()
                    },
                ))
                .ok()
                .map(|a| a.get_info());
                let taken = preferred.and_then(|p| infos.iter().position(|i| *i == p));
                (Choice::Default, taken)
            }
        };
        AdapterListing {
            api: format!("{api:?}"),
            adapters,
            choice,
            taken,
        }
    }

    fn kind(device_type: wgpu::DeviceType) -> AdapterKind {
        match device_type {
            wgpu::DeviceType::DiscreteGpu => AdapterKind::DiscreteGpu,
            wgpu::DeviceType::IntegratedGpu => AdapterKind::IntegratedGpu,
            wgpu::DeviceType::VirtualGpu => AdapterKind::VirtualGpu,
            wgpu::DeviceType::Cpu => AdapterKind::Cpu,
            wgpu::DeviceType::Other => AdapterKind::Other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{Adapter, AdapterKind, Selector, picked_by, selectors};
    use AdapterKind::*;

    fn adapter(selector: Selector) -> Adapter {
        Adapter {
            selector,
            kind: selector.kind,
            name: String::new(),
            driver: String::new(),
            pci_bus: String::new(),
        }
    }

    /// CubeCL 0.11 (`adapter_device_ids` in cubecl-wgpu's runtime.rs): each type counts from
    /// zero in enumeration order, a CPU adapter has no index.
    #[test]
    fn each_type_counts_from_zero_on_its_own() {
        let listed = selectors(&[IntegratedGpu, DiscreteGpu, Cpu, DiscreteGpu, Other, Cpu]);
        let words: Vec<String> = listed.iter().map(ToString::to_string).collect();
        assert_eq!(
            words,
            [
                "IntegratedGpu(0)",
                "DiscreteGpu(0)",
                "Cpu",
                "DiscreteGpu(1)",
                "Other(0)",
                "Cpu"
            ]
        );
    }

    /// The words CubeCL's `try_device_override` accepts and refuses.
    #[test]
    fn the_variable_is_read_as_cubecl_reads_it() {
        let some = |kind, index| Some(Selector { kind, index });
        assert_eq!(Selector::parse("Cpu"), some(Cpu, 0));
        assert_eq!(Selector::parse("DiscreteGpu(3)"), some(DiscreteGpu, 3));
        assert_eq!(Selector::parse("IntegratedGpu(0)"), some(IntegratedGpu, 0));
        assert_eq!(Selector::parse("VirtualGpu(12)"), some(VirtualGpu, 12));
        assert_eq!(Selector::parse("Other(1)"), some(Other, 1));
        for refused in [
            "",
            "cpu",
            "DiscreteGpu",
            "DiscreteGpu()",
            "DiscreteGpu(-1)",
            "Gpu(0)",
        ] {
            assert_eq!(Selector::parse(refused), None, "{refused:?}");
        }
        for selector in selectors(&[DiscreteGpu, DiscreteGpu, Cpu, VirtualGpu]) {
            assert_eq!(Selector::parse(&selector.to_string()), Some(selector));
        }
    }

    #[test]
    fn a_value_picks_the_adapter_it_names_or_none() {
        let listed: Vec<Adapter> = selectors(&[DiscreteGpu, Cpu, DiscreteGpu])
            .into_iter()
            .map(adapter)
            .collect();
        assert_eq!(picked_by("DiscreteGpu(1)", &listed), Some(2));
        assert_eq!(picked_by("Cpu", &listed), Some(1));
        assert_eq!(picked_by("DiscreteGpu(2)", &listed), None);
        assert_eq!(picked_by("IntegratedGpu(0)", &listed), None);
        assert_eq!(picked_by("Bogus", &listed), None);
    }
}
