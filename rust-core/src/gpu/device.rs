//! The one wgpu device, created on first use, with buffer helpers and a cache of compute
//! pipelines keyed by (shader, entry point).

use super::no_adapter;
use crate::error::{Error, Result};
use std::cell::Cell;
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};
use wgpu::util::DeviceExt;

/// Threads per workgroup of every kernel (`@workgroup_size(64)` in the shaders).
pub(crate) const WORKGROUP: u32 = 64;

/// Adapter, device and queue, and the pipelines built so far.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    /// Adapter name, driver and device type, for stats and messages.
    pub name: String,
    /// A software rasteriser (lavapipe, llvmpipe, WARP): correct, but slower than the CPU
    /// path, so `Backend::Auto` does not pick it.
    pub software: bool,
    pipelines: Mutex<HashMap<(&'static str, &'static str), wgpu::ComputePipeline>>,
}

/// Host-to-device traffic and kernel launches of the calling thread: counts of work,
/// independent of the machine's load, for the benchmarks and the tests that check what a
/// step uploads. Per thread, so that tests running side by side do not see each other's
/// traffic (every upload, dispatch and read-back happens on the thread that asked).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Transfers {
    /// Buffers created with contents (storage and uniform).
    pub uploads: u64,
    /// Their bytes.
    pub upload_bytes: u64,
    /// Kernel dispatches.
    pub dispatches: u64,
    /// Read-backs (one map each).
    pub readbacks: u64,
}

impl std::ops::Sub for Transfers {
    type Output = Transfers;
    fn sub(self, o: Transfers) -> Transfers {
        Transfers {
            uploads: self.uploads - o.uploads,
            upload_bytes: self.upload_bytes - o.upload_bytes,
            dispatches: self.dispatches - o.dispatches,
            readbacks: self.readbacks - o.readbacks,
        }
    }
}

thread_local! {
    static TRANSFERS: Cell<Transfers> = const {
        Cell::new(Transfers {
            uploads: 0,
            upload_bytes: 0,
            dispatches: 0,
            readbacks: 0,
        })
    };
}

/// The device, created on first call; the error (no adapter, no device) is remembered.
pub fn get() -> Result<&'static Gpu> {
    static GPU: OnceLock<std::result::Result<Gpu, String>> = OnceLock::new();
    GPU.get_or_init(create)
        .as_ref()
        .map_err(|why| no_adapter(why))
}

fn create() -> std::result::Result<Gpu, String> {
    let quiet = QuietDeviceSelect::new();
    // WGPU_BACKEND (e.g. vulkan) narrows the probe; without it every compiled backend.
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: None,
        apply_limit_buckets: false,
    }))
    .map_err(|e| format!("{e} (install a Vulkan driver, e.g. Debian's mesa-vulkan-drivers)"))?;
    drop(quiet);
    let info = adapter.get_info();
    let name = format!(
        "{} ({:?}, {:?}, {})",
        info.name, info.backend, info.device_type, info.driver
    );
    let software = info.device_type == wgpu::DeviceType::Cpu;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("isobar"),
        required_features: wgpu::Features::empty(),
        required_limits: adapter.limits(),
        ..Default::default()
    }))
    .map_err(|e| format!("{name} refused a device: {e}"))?;
    Ok(Gpu {
        device,
        queue,
        name,
        software,
        pipelines: Mutex::new(HashMap::new()),
    })
}

/// Mesa's implicit Vulkan layer VK_LAYER_MESA_device_select connects to a Wayland
/// compositor while it lists the devices, to rank the one showing the desktop first.
/// Without a session (a server, a notebook kernel, CI: no XDG_RUNTIME_DIR) libwayland
/// prints "error: XDG_RUNTIME_DIR is invalid or not set in the environment." twice on
/// stderr, which Jupyter shows in red although the run is fine. With no session there is
/// no desktop to rank, so for the probe alone the layer is switched off the way its
/// manifest offers (NODEVICE_SELECT=1), and the environment is put back after it. The
/// probe runs once per process (`get`'s OnceLock).
struct QuietDeviceSelect(bool);

impl QuietDeviceSelect {
    fn new() -> QuietDeviceSelect {
        let session = ["XDG_RUNTIME_DIR", "WAYLAND_DISPLAY", "NODEVICE_SELECT"]
            .iter()
            .any(|v| std::env::var_os(v).is_some());
        if cfg!(target_os = "linux") && !session {
            std::env::set_var("NODEVICE_SELECT", "1");
            QuietDeviceSelect(true)
        } else {
            QuietDeviceSelect(false)
        }
    }
}

impl Drop for QuietDeviceSelect {
    fn drop(&mut self) {
        if self.0 {
            std::env::remove_var("NODEVICE_SELECT");
        }
    }
}

/// A failure while running a kernel, worded for the user.
pub fn gpu_error(what: impl std::fmt::Display) -> Error {
    Error::InvalidInput(format!("GPU: {what}"))
}

impl Gpu {
    /// The calling thread's traffic so far.
    pub fn transfers(&self) -> Transfers {
        TRANSFERS.get()
    }

    fn count(&self, add: impl FnOnce(&mut Transfers)) {
        let mut t = TRANSFERS.get();
        add(&mut t);
        TRANSFERS.set(t);
    }

    fn count_upload(&self, bytes: usize) {
        self.count(|t| {
            t.uploads += 1;
            t.upload_bytes += bytes as u64;
        });
    }

    /// A storage buffer holding `data` (at least 16 bytes: empty bindings are invalid).
    pub fn upload<T: bytemuck::Pod>(&self, label: &str, data: &[T]) -> wgpu::Buffer {
        let mut bytes = bytemuck::cast_slice::<T, u8>(data).to_vec();
        bytes.resize(bytes.len().max(16).next_multiple_of(4), 0);
        self.count_upload(bytes.len());
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: &bytes,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// A uniform buffer holding `value`.
    pub fn uniform<T: bytemuck::Pod>(&self, label: &str, value: &T) -> wgpu::Buffer {
        self.count_upload(std::mem::size_of::<T>());
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::bytes_of(value),
                usage: wgpu::BufferUsages::UNIFORM,
            })
    }

    /// A zeroed storage buffer of `count` elements of `T`, refused when larger than the
    /// device allows.
    pub fn zeroed<T: bytemuck::Pod>(&self, label: &str, count: usize) -> Result<wgpu::Buffer> {
        let bytes = (count * std::mem::size_of::<T>())
            .max(16)
            .next_multiple_of(4) as u64;
        let limits = self.device.limits();
        let max = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if bytes > max {
            return Err(Error::OverBudget {
                what: format!("GPU buffer '{label}'"),
                needed_bytes: bytes,
                budget_bytes: max,
            });
        }
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        }))
    }

    /// Runs `entry` of `source` over `threads` invocations with `bindings` as
    /// (binding, buffer) pairs of group 0. Threads beyond 65535 workgroups spill into y;
    /// kernels compute their index as `gid.x + gid.y * nwg.x * 64` and stop at their count.
    pub fn dispatch(
        &self,
        source: (&'static str, &'static str),
        entry: &'static str,
        bindings: &[(u32, &wgpu::Buffer)],
        threads: u64,
    ) -> Result<()> {
        if threads == 0 {
            return Ok(());
        }
        let pipeline = self.pipeline(source, entry);
        let layout = pipeline.get_bind_group_layout(0);
        let entries: Vec<wgpu::BindGroupEntry> = bindings
            .iter()
            .map(|&(binding, buffer)| wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            })
            .collect();
        let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(entry),
            layout: &layout,
            entries: &entries,
        });
        let groups = threads.div_ceil(WORKGROUP as u64);
        let max = self.device.limits().max_compute_workgroups_per_dimension as u64;
        let x = groups.min(max);
        let y = groups.div_ceil(x);
        if y > max {
            return Err(gpu_error(format!(
                "{threads} threads of '{entry}' exceed the device's dispatch size"
            )));
        }
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(entry) });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(entry),
                timestamp_writes: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(x as u32, y as u32, 1);
        }
        self.queue.submit([encoder.finish()]);
        self.count(|t| t.dispatches += 1);
        Ok(())
    }

    fn pipeline(
        &self,
        source: (&'static str, &'static str),
        entry: &'static str,
    ) -> wgpu::ComputePipeline {
        let mut cache = self.pipelines.lock().unwrap_or_else(|e| e.into_inner());
        cache
            .entry((source.0, entry))
            .or_insert_with(|| {
                let module = self
                    .device
                    .create_shader_module(wgpu::ShaderModuleDescriptor {
                        label: Some(source.0),
                        source: wgpu::ShaderSource::Wgsl(source.1.into()),
                    });
                self.device
                    .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(entry),
                        layout: None,
                        module: &module,
                        entry_point: Some(entry),
                        compilation_options: Default::default(),
                        cache: None,
                    })
            })
            .clone()
    }

    /// The first `count` elements of `buffer`, after every submitted kernel has run.
    pub fn read<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, count: usize) -> Result<Vec<T>> {
        self.read_at(buffer, 0, count)
    }

    /// `count` elements of `buffer` from element `first` (whose byte offset must be a
    /// multiple of 4), after every submitted kernel has run.
    pub fn read_at<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        first: usize,
        count: usize,
    ) -> Result<Vec<T>> {
        let offset = (first * std::mem::size_of::<T>()) as u64;
        let bytes = (count * std::mem::size_of::<T>()) as u64;
        if bytes == 0 {
            return Ok(Vec::new());
        }
        let size = bytes.next_multiple_of(4);
        self.count(|t| t.readbacks += 1);
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(gpu_error)?;
        rx.recv().map_err(gpu_error)?.map_err(gpu_error)?;
        let view = staging.get_mapped_range(..).map_err(gpu_error)?;
        let out = bytemuck::pod_collect_to_vec::<u8, T>(&view[..bytes as usize]);
        drop(view);
        staging.unmap();
        Ok(out)
    }
}
