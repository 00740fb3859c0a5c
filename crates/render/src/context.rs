//! The wgpu instance, adapter, device and queue, with the limits slosh needs checked up front.

use std::sync::OnceLock;

use crate::bindings::layout_entries;
use crate::error::{Error, Result};
use crate::shaders::{FRAME_ARRAYS, MASK_ARRAYS, RANGES, STEP_ARRAYS, TREE_ARRAYS};

/// Storage buffers bound per shader stage by the step, frame, mask and tree bind groups: every
/// array in `RANGES` bindings.
pub const STORAGE_BUFFERS_NEEDED: u32 =
    (STEP_ARRAYS.len() + FRAME_ARRAYS.len() + MASK_ARRAYS.len() + TREE_ARRAYS.len()) as u32
        * RANGES;

/// The smallest binding limit [`Gpu::limit_bindings`] takes (ranges stay aligned above it).
pub const MIN_BINDING_LIMIT: u64 = 1 << 16;

/// A GPU device ready for slosh's passes.
#[derive(Debug)]
pub struct Gpu {
    /// The instance the adapter came from, where this `Gpu` made it (a window toolkit that
    /// shares the device needs it for its surfaces).
    pub instance: Option<wgpu::Instance>,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    /// Whether compute passes can write GPU timestamps (frame times in `slosh bench gpu`).
    pub timestamps: bool,
    /// The trace and shade passes' step bind group layout (group 0), shared by every step's
    /// bind group and the tracer's pipelines.
    step_layout: OnceLock<wgpu::BindGroupLayout>,
    /// The largest storage binding used, in bytes: the adapter's, or lower
    /// ([`Gpu::limit_bindings`]).
    binding_limit: u64,
}

/// The Vulkan adapters wgpu can see (the tracer binds more storage buffers than GL allows),
/// with the instance that found them: listed once, looked at, then one opened
/// ([`Gpu::from_adapters`]) without listing them again.
#[derive(Debug)]
pub struct Adapters {
    instance: wgpu::Instance,
    adapters: Vec<wgpu::Adapter>,
}

impl Adapters {
    pub fn list() -> Adapters {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN));
        Adapters { instance, adapters }
    }

    /// What each adapter is, in the order listed.
    pub fn infos(&self) -> Vec<wgpu::AdapterInfo> {
        self.adapters.iter().map(wgpu::Adapter::get_info).collect()
    }
}

fn describe(info: &wgpu::AdapterInfo) -> String {
    format!(
        "{} ({:?}, {:?}, driver {} {})",
        info.name, info.backend, info.device_type, info.driver, info.driver_info
    )
}

impl Gpu {
    /// Opens the first adapter whose name contains `name` (case-insensitive), or the best one:
    /// a discrete GPU before an integrated one before a software rasteriser.
    pub fn new(name: Option<&str>) -> Result<Gpu> {
        Gpu::from_adapters(Adapters::list(), name)
    }

    /// [`Gpu::new`] among adapters listed already.
    pub fn from_adapters(listed: Adapters, name: Option<&str>) -> Result<Gpu> {
        let Adapters {
            instance,
            adapters: mut candidates,
        } = listed;
        if candidates.is_empty() {
            return Err(Error::NoAdapter(
                "wgpu found no Vulkan adapter (install a driver, e.g. mesa-vulkan-drivers for lavapipe)"
                    .into(),
            ));
        }
        if let Some(name) = name {
            let wanted = name.to_lowercase();
            let seen: Vec<String> = candidates.iter().map(|a| describe(&a.get_info())).collect();
            candidates.retain(|a| a.get_info().name.to_lowercase().contains(&wanted));
            if candidates.is_empty() {
                return Err(Error::NoAdapter(format!(
                    "no adapter name contains '{name}'; found: {}",
                    seen.join("; ")
                )));
            }
        }
        let rank = |a: &wgpu::Adapter| match a.get_info().device_type {
            wgpu::DeviceType::DiscreteGpu => 0,
            wgpu::DeviceType::IntegratedGpu => 1,
            wgpu::DeviceType::VirtualGpu => 2,
            wgpu::DeviceType::Cpu => 3,
            wgpu::DeviceType::Other => 4,
        };
        candidates.sort_by_key(rank);
        let adapter = candidates.remove(0);
        let mut gpu = Gpu::open(adapter)?;
        gpu.instance = Some(instance);
        Ok(gpu)
    }

    fn open(adapter: wgpu::Adapter) -> Result<Gpu> {
        let info = adapter.get_info();
        let limits = Gpu::required_limits(&adapter)?;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("slosh"),
            required_features: Gpu::wanted_features(&adapter),
            required_limits: limits,
            experimental_features: wgpu::ExperimentalFeatures::default(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|source| Error::Device {
            adapter: describe(&info),
            source,
        })?;
        Gpu::from_parts(adapter, device, queue)
    }

    /// The limits to ask `adapter` for when creating a device for slosh elsewhere (eframe's
    /// egui-wgpu, say): the storage buffers the passes bind, and the adapter's largest
    /// bindings, buffers and dispatches. An error where the adapter cannot bind enough.
    pub fn required_limits(adapter: &wgpu::Adapter) -> Result<wgpu::Limits> {
        let available = adapter.limits();
        if available.max_storage_buffers_per_shader_stage < STORAGE_BUFFERS_NEEDED
            || available.max_buffers_and_acceleration_structures_per_shader_stage
                < STORAGE_BUFFERS_NEEDED + 1
        {
            return Err(Error::Limits {
                adapter: describe(&adapter.get_info()),
                problem: format!(
                    "allows {} storage buffers and {} buffers in all per shader stage; the tracer binds {STORAGE_BUFFERS_NEEDED} and a uniform block",
                    available.max_storage_buffers_per_shader_stage,
                    available.max_buffers_and_acceleration_structures_per_shader_stage
                ),
            });
        }
        Ok(wgpu::Limits {
            max_storage_buffers_per_shader_stage: STORAGE_BUFFERS_NEEDED,
            // The uniform blocks count here too.
            max_buffers_and_acceleration_structures_per_shader_stage: available
                .max_buffers_and_acceleration_structures_per_shader_stage,
            max_storage_buffer_binding_size: available.max_storage_buffer_binding_size,
            max_buffer_size: available.max_buffer_size,
            max_compute_workgroups_per_dimension: available.max_compute_workgroups_per_dimension,
            // A window's surface is a texture: the default (8192) is less than a large
            // monitor wall or a window an X client sizes at will.
            max_texture_dimension_2d: available.max_texture_dimension_2d,
            ..wgpu::Limits::default()
        })
    }

    /// The optional features slosh uses where `adapter` has them: timestamp queries (frame
    /// times). A device created elsewhere may ask for them too.
    pub fn wanted_features(adapter: &wgpu::Adapter) -> wgpu::Features {
        adapter.features() & wgpu::Features::TIMESTAMP_QUERY
    }

    /// A `Gpu` over a device and queue someone else created (eframe's egui-wgpu, say), which
    /// should have asked for [`Gpu::required_limits`] and [`Gpu::wanted_features`]; an error
    /// naming the shortfall where the device cannot run the passes.
    pub fn from_parts(
        adapter: wgpu::Adapter,
        device: wgpu::Device,
        queue: wgpu::Queue,
    ) -> Result<Gpu> {
        let info = adapter.get_info();
        let limits = device.limits();
        if limits.max_storage_buffers_per_shader_stage < STORAGE_BUFFERS_NEEDED {
            return Err(Error::Limits {
                adapter: describe(&info),
                problem: format!(
                    "the device was created with {} storage buffers per shader stage; the tracer binds {STORAGE_BUFFERS_NEEDED} (create it with Gpu::required_limits)",
                    limits.max_storage_buffers_per_shader_stage
                ),
            });
        }
        // The balls' half floats are unpacked by `unpack2x16float` (every Vulkan, Metal and
        // DX12 adapter has it; GLES may not).
        if !adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::SHADER_F16_IN_F32)
        {
            return Err(Error::Limits {
                adapter: describe(&info),
                problem: "the adapter cannot unpack half floats in shaders (SHADER_F16_IN_F32)"
                    .into(),
            });
        }
        let timestamps = device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let binding_limit = limits.max_storage_buffer_binding_size;
        Ok(Gpu {
            instance: None,
            adapter,
            device,
            queue,
            info,
            timestamps,
            step_layout: OnceLock::new(),
            binding_limit,
        })
    }

    /// "NAME (backend, type, driver …)".
    pub fn describe(&self) -> String {
        describe(&self.info)
    }

    /// Bytes of device-local memory, where the adapter is a Vulkan one (the sum of its
    /// device-local heaps; wgpu itself does not report memory). A software rasteriser's
    /// "device-local" heap is system memory.
    pub fn device_memory(&self) -> Option<u64> {
        // SAFETY: the hal adapter is only read (its physical device's memory properties), while
        // `self.adapter` keeps it alive.
        let hal = unsafe { self.adapter.as_hal::<wgpu::hal::api::Vulkan>() }?;
        let instance = hal.shared_instance().raw_instance();
        // SAFETY: the physical device belongs to this instance.
        let properties =
            unsafe { instance.get_physical_device_memory_properties(hal.raw_physical_device()) };
        let heaps = &properties.memory_heaps[..properties.memory_heap_count as usize];
        let local: u64 = heaps
            .iter()
            .filter(|h| h.flags.contains(ash::vk::MemoryHeapFlags::DEVICE_LOCAL))
            .map(|h| h.size)
            .sum();
        (local > 0).then_some(local)
    }

    /// The step bind group layout (group 0 of the trace and shade passes).
    pub fn step_layout(&self) -> &wgpu::BindGroupLayout {
        self.step_layout.get_or_init(|| {
            self.device
                .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some("step"),
                    entries: &layout_entries(&STEP_ARRAYS, false),
                })
        })
    }

    /// The largest storage binding used, in bytes; arrays span up to `RANGES` of them.
    pub fn max_binding(&self) -> u64 {
        self.binding_limit
    }

    /// Binds storage in slices of at most `bytes` (at least [`MIN_BINDING_LIMIT`], at most
    /// the adapter's limit): how the splitting of large arrays is tested on small scenes.
    /// Applies to steps uploaded and tracers built afterwards.
    pub fn limit_bindings(&mut self, bytes: u64) {
        let adapter = self.device.limits().max_storage_buffer_binding_size;
        self.binding_limit = bytes.clamp(MIN_BINDING_LIMIT.min(adapter), adapter);
    }

    /// Blocks until the GPU has finished all submitted work.
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| Error::Readback(e.to_string()))
    }

    /// Blocks until the submission `index` (and every one before it) has run, not the ones
    /// other threads made since: bake jobs sharing the device each wait for their own work
    /// instead of everyone's.
    pub fn wait_for(&self, index: wgpu::SubmissionIndex) -> Result<()> {
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(index),
                timeout: None,
            })
            .map(|_| ())
            .map_err(|e| Error::Readback(e.to_string()))
    }
}
