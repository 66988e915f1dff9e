//! The device a simulation runs on and what the backend knows about it.
//!
//! A simulation either acquires its own adapter and device ([`Gpu::acquire`], what
//! [`GpuSimulation::new`] does) or is given a caller's device and queue ([`Gpu::shared`], for
//! [`GpuSimulation::on_device`], so that a renderer can draw the rods from the buffers of the
//! device it already has). Either way the rest of the backend sees one [`Gpu`]: the device, the
//! queue, the limits and features the device was created with, and an [`AdapterSummary`] that
//! holds what the plan needs to know about the hardware, including the table of adapters whose
//! workgroups are known to be co-resident (the multi-workgroup path's precondition).
//!
//! [`GpuSimulation::new`]: crate::GpuSimulation::new
//! [`GpuSimulation::on_device`]: crate::GpuSimulation::on_device

use crate::{GpuError, GpuOptions};
use std::sync::{Arc, Mutex};

/// What the backend learned about its adapter.
#[derive(Clone, Debug, PartialEq)]
pub struct AdapterSummary {
    /// Adapter name as the driver reports it (e.g. "NVIDIA H100 80GB HBM3", "llvmpipe (…)").
    pub name: String,
    /// Driver name and version info.
    pub driver: String,
    /// PCI vendor id.
    pub vendor: u32,
    /// Whether this is a software (CPU) adapter such as lavapipe.
    pub software: bool,
    /// Whether GPU timestamps can be recorded.
    pub timestamps: bool,
    /// Workgroups known to be co-resident, when known.
    pub co_resident_workgroups: Option<u32>,
    /// Largest workgroup memory in bytes.
    pub max_workgroup_storage: u32,
    /// The subgroup size, when the adapter has subgroup operations and one fixed size (the
    /// subgroup layout for short rods needs both).
    pub subgroup_size: Option<u32>,
    /// Whether storage buffers can be declared `@coherent` (the multi-workgroup halo exchange
    /// then moves vec4s through one instead of single words through atomics).
    pub coherent: bool,
}

/// Device errors wgpu reports outside an error scope, kept until the simulation's next call
/// returns them. Only a device the simulation acquired itself reports into one: a shared
/// device keeps its owner's handler.
#[derive(Clone, Default)]
pub(crate) struct ErrorSink(Arc<Mutex<Option<String>>>);

impl ErrorSink {
    /// A sink that receives `device`'s uncaptured errors (the first one is kept).
    fn installed_on(device: &wgpu::Device) -> Self {
        let sink = Self::default();
        let slot = sink.0.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut slot = slot.lock().unwrap_or_else(|p| p.into_inner());
            slot.get_or_insert_with(|| e.to_string());
        }));
        sink
    }

    /// The first error reported since the last call, as a [`GpuError::Wgpu`].
    pub(crate) fn take(&self) -> Result<(), GpuError> {
        match self.0.lock().unwrap_or_else(|p| p.into_inner()).take() {
            Some(e) => Err(GpuError::Wgpu(e)),
            None => Ok(()),
        }
    }
}

/// A device and queue with what the plan and the upload need to know about them.
pub(crate) struct Gpu {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pub(crate) adapter: AdapterSummary,
    /// The limits the device was created with.
    pub(crate) limits: wgpu::Limits,
    pub(crate) errors: ErrorSink,
}

impl Gpu {
    /// Requests a high-performance adapter and a device with its full limits and the optional
    /// features the kernels use where it has them (subgroups, `@coherent` buffers, and
    /// timestamps when `options.timestamps` asks for them).
    pub(crate) fn acquire(options: &GpuOptions) -> Result<Self, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        Self::open(&adapter, options)
    }

    /// A device on each of `count` distinct adapters (`None`: every one), hardware adapters
    /// before software ones and in bus order, so that a batch split across them lands on the
    /// same cards from run to run. An adapter that several graphics APIs expose is taken once.
    pub(crate) fn acquire_each(
        options: &GpuOptions,
        count: Option<usize>,
    ) -> Result<Vec<Self>, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let all = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        let adapters = distinct_adapters(all.iter().map(wgpu::Adapter::get_info).collect())
            .into_iter()
            .map(|i| &all[i])
            .collect::<Vec<_>>();
        let names = || {
            adapters
                .iter()
                .map(|a| a.get_info().name)
                .collect::<Vec<_>>()
                .join(", ")
        };
        let take = match count {
            Some(0) => {
                return Err(GpuError::InvalidInput(
                    "gpus = 0: a simulation needs at least one adapter".into(),
                ));
            }
            Some(n) if n > adapters.len() => {
                return Err(GpuError::NoAdapter(format!(
                    "gpus = {n}, but {} adapter{} found ({})",
                    adapters.len(),
                    if adapters.len() == 1 {
                        " was"
                    } else {
                        "s were"
                    },
                    names()
                )));
            }
            Some(n) => n,
            None if adapters.is_empty() => {
                return Err(GpuError::NoAdapter("no adapter was found".into()));
            }
            None => adapters.len(),
        };
        adapters[..take]
            .iter()
            .map(|a| Self::open(a, options))
            .collect()
    }

    /// A device on `adapter` with its full limits and the optional features the kernels use.
    fn open(adapter: &wgpu::Adapter, options: &GpuOptions) -> Result<Self, GpuError> {
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("cosserat-backend-gpu"),
            required_features: wanted_features(adapter.features(), options),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(format!("adapter `{}` gave no device: {e}", info.name)))?;
        let errors = ErrorSink::installed_on(&device);
        Ok(Self::with_errors(device, queue, errors, options))
    }

    /// Waits until the device has finished everything submitted (two minutes at most), then
    /// reports any error it raised meanwhile.
    pub(crate) fn wait_idle(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: Some(std::time::Duration::from_secs(120)),
            })
            .map_err(|e| GpuError::Wgpu(format!("waiting for the GPU: {e}")))?;
        self.errors.take()
    }

    /// A caller's device and queue. The features and limits are those the device was created
    /// with; its uncaptured-error handler is left to its owner.
    pub(crate) fn shared(device: wgpu::Device, queue: wgpu::Queue, options: &GpuOptions) -> Self {
        Self::with_errors(device, queue, ErrorSink::default(), options)
    }

    fn with_errors(
        device: wgpu::Device,
        queue: wgpu::Queue,
        errors: ErrorSink,
        options: &GpuOptions,
    ) -> Self {
        let adapter = summarize(
            &device.adapter_info(),
            device.features(),
            &device.limits(),
            options,
        );
        let limits = device.limits();
        Self {
            device,
            queue,
            adapter,
            limits,
            errors,
        }
    }
}

/// Indices of the adapters to use, one per physical device: hardware adapters (or, when there
/// are none, software ones) of the primary graphics APIs (Vulkan, Metal, DX12; GL only where
/// none of them has one, since GL lists the same cards again under other names and ids), each
/// device once, in PCI bus order where known.
fn distinct_adapters(infos: Vec<wgpu::AdapterInfo>) -> Vec<usize> {
    let software = |i: &wgpu::AdapterInfo| {
        i.device_type == wgpu::DeviceType::Cpu || i.name.to_ascii_lowercase().contains("llvmpipe")
    };
    let primary = |i: &wgpu::AdapterInfo| wgpu::Backends::PRIMARY.contains(i.backend.into());
    let any_hardware = infos.iter().any(|i| !software(i));
    let any_primary = infos
        .iter()
        .any(|i| primary(i) && software(i) != any_hardware);
    let mut seen = Vec::new();
    let mut chosen: Vec<usize> = Vec::new();
    for (k, info) in infos.iter().enumerate() {
        if software(info) == any_hardware || (any_primary && !primary(info)) {
            continue;
        }
        let identity = (
            info.vendor,
            info.device,
            if info.device_pci_bus_id.is_empty() {
                info.name.clone()
            } else {
                info.device_pci_bus_id.clone()
            },
        );
        if seen.contains(&identity) {
            continue;
        }
        seen.push(identity);
        chosen.push(k);
    }
    chosen.sort_by(|&a, &b| infos[a].device_pci_bus_id.cmp(&infos[b].device_pci_bus_id));
    chosen
}

/// The optional features of `available` the kernels use: subgroups, `@coherent` buffers and
/// double precision (the stiff scheme's banded solve, `banded.rs`) always, timestamps when
/// asked for.
fn wanted_features(available: wgpu::Features, options: &GpuOptions) -> wgpu::Features {
    let mut wanted = wgpu::Features::SUBGROUP
        | wgpu::Features::MEMORY_DECORATION_COHERENT
        | wgpu::Features::SHADER_F64;
    if options.timestamps {
        wanted |= wgpu::Features::TIMESTAMP_QUERY;
    }
    available & wanted
}

/// What the plan needs to know about an adapter whose device has `features` and `limits`.
fn summarize(
    info: &wgpu::AdapterInfo,
    features: wgpu::Features,
    limits: &wgpu::Limits,
    options: &GpuOptions,
) -> AdapterSummary {
    let software = info.device_type == wgpu::DeviceType::Cpu
        || info.name.to_ascii_lowercase().contains("llvmpipe");
    let has_subgroups = features.contains(wgpu::Features::SUBGROUP);
    AdapterSummary {
        name: info.name.clone(),
        driver: format!("{} {}", info.driver, info.driver_info)
            .trim()
            .to_string(),
        vendor: info.vendor,
        software,
        timestamps: options.timestamps && features.contains(wgpu::Features::TIMESTAMP_QUERY),
        co_resident_workgroups: options.co_resident_workgroups.or(if software {
            None
        } else {
            known_co_residency(info)
        }),
        max_workgroup_storage: limits.max_compute_workgroup_storage_size,
        // The layout puts one rod on SG consecutive invocations and relies on them forming
        // one subgroup, so the size must be fixed (NVIDIA: 32, lavapipe: 8).
        subgroup_size: (has_subgroups
            && info.subgroup_min_size == info.subgroup_max_size
            && info.subgroup_min_size >= 4)
            .then_some(info.subgroup_min_size),
        coherent: features.contains(wgpu::Features::MEMORY_DECORATION_COHERENT),
    }
}

/// Workgroups known to be co-resident on the adapter `info` describes, from a table of
/// measured GPUs; `None` for every other adapter.
fn known_co_residency(info: &wgpu::AdapterInfo) -> Option<u32> {
    // One workgroup per SM is far below what was measured co-resident (8 per SM of 256 threads
    // on the H100, GPU.md) and leaves room for the kernel's registers and workgroup memory.
    let name = info.name.to_ascii_uppercase();
    if info.vendor != 0x10de {
        return None;
    }
    if name.contains("H100") && name.contains("PCIE") {
        Some(114)
    } else if name.contains("H100") || name.contains("H200") || name.contains("GH200") {
        Some(132)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info(name: &str, vendor: u32, device_type: wgpu::DeviceType) -> wgpu::AdapterInfo {
        wgpu::AdapterInfo {
            name: name.into(),
            vendor,
            device_type,
            ..wgpu::AdapterInfo::new(device_type, wgpu::Backend::Vulkan)
        }
    }

    #[test]
    fn co_residency_is_known_only_for_measured_gpus() {
        let gpu = wgpu::DeviceType::DiscreteGpu;
        assert_eq!(
            known_co_residency(&info("NVIDIA H100 80GB HBM3", 0x10de, gpu)),
            Some(132)
        );
        assert_eq!(
            known_co_residency(&info("NVIDIA H100 PCIe", 0x10de, gpu)),
            Some(114)
        );
        assert_eq!(
            known_co_residency(&info("NVIDIA H200", 0x10de, gpu)),
            Some(132)
        );
        assert_eq!(
            known_co_residency(&info("NVIDIA RTX 4090", 0x10de, gpu)),
            None
        );
        assert_eq!(
            known_co_residency(&info("H100 lookalike", 0x1002, gpu)),
            None
        );
    }

    #[test]
    fn each_card_is_taken_once_from_the_primary_apis() {
        let gpu = wgpu::DeviceType::DiscreteGpu;
        let card = |name: &str, backend: wgpu::Backend, bus: &str| wgpu::AdapterInfo {
            device: 0x2330,
            device_pci_bus_id: bus.into(),
            backend,
            ..info(name, 0x10de, gpu)
        };
        let infos = vec![
            card(
                "NVIDIA H100 80GB HBM3",
                wgpu::Backend::Vulkan,
                "0000:1b:00.0",
            ),
            card(
                "NVIDIA H100 80GB HBM3",
                wgpu::Backend::Vulkan,
                "0000:0a:00.0",
            ),
            card("NVIDIA H100 80GB HBM3/PCIe/SSE2", wgpu::Backend::Gl, ""),
            info(
                "llvmpipe (LLVM 17, 256 bits)",
                0x10005,
                wgpu::DeviceType::Cpu,
            ),
        ];
        // Two cards, in bus order; neither GL's listing nor the software adapter.
        assert_eq!(distinct_adapters(infos), vec![1, 0]);
        // A machine with only a software adapter uses it.
        let lavapipe = info(
            "llvmpipe (LLVM 17, 256 bits)",
            0x10005,
            wgpu::DeviceType::Cpu,
        );
        assert_eq!(distinct_adapters(vec![lavapipe]), vec![0]);
    }

    #[test]
    fn software_adapters_never_claim_co_residency() {
        let options = GpuOptions::default();
        let lavapipe = info(
            "llvmpipe (LLVM 17, 256 bits)",
            0x10005,
            wgpu::DeviceType::Cpu,
        );
        let s = summarize(
            &lavapipe,
            wgpu::Features::empty(),
            &wgpu::Limits::default(),
            &options,
        );
        assert!(s.software && s.co_resident_workgroups.is_none() && s.subgroup_size.is_none());
        // What the caller asserts wins over the table, also on a software adapter.
        let asserted = GpuOptions {
            co_resident_workgroups: Some(4),
            ..options
        };
        let s = summarize(
            &lavapipe,
            wgpu::Features::empty(),
            &wgpu::Limits::default(),
            &asserted,
        );
        assert_eq!(s.co_resident_workgroups, Some(4));
    }
}
