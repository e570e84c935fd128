//! Finding an adapter and creating the device: Vulkan first (lavapipe on GPU-less machines),
//! then GL; `WGPU_BACKEND` overrides. Validation errors are captured instead of panicking
//! (wgpu's default handler panics). The one device setup of the workspace: the voxelizer
//! and `voxlod-render` (pictures and the streaming viewer) both open their device with
//! [`open_device`]. Notes on wgpu 30 with lavapipe: `../shared/notes/wgpu-30-on-lavapipe.md`
//! (the adapter's own limits are requested: wgpu's defaults cap buffers at 256 MiB).

use std::sync::{Arc, Mutex};

use crate::GpuError;

/// A device with its queue and the first uncaptured error, if any.
pub struct Gpu {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Name, backend and driver of the adapter.
    pub name: String,
    /// The adapter's description (name, backend, device type).
    pub info: wgpu::AdapterInfo,
    /// The adapter (a window's surface asks it for its capabilities).
    pub adapter: wgpu::Adapter,
    /// `SHADER_F64` was asked for and is enabled.
    pub f64: bool,
    /// A CPU-emulated device (lavapipe, llvmpipe, WARP).
    pub software: bool,
    /// The limits the device was created with (the adapter's own).
    pub limits: wgpu::Limits,
    /// The first error the device reported since the last [`Gpu::check`].
    pub error: Arc<Mutex<Option<String>>>,
}

fn request(backends: Option<wgpu::Backends>) -> Result<wgpu::Adapter, String> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if let Some(b) = backends {
        desc.backends = b;
    }
    let instance = wgpu::Instance::new(desc);
    pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: None,
        ..Default::default()
    }))
    .map_err(|e| e.to_string())
}

/// The adapter [`open`] uses: `WGPU_BACKEND` if set, else Vulkan, else GL.
fn find_adapter() -> Result<wgpu::Adapter, GpuError> {
    if std::env::var_os("WGPU_BACKEND").is_some() {
        request(None).map_err(GpuError::NoAdapter)
    } else {
        match request(Some(wgpu::Backends::VULKAN)) {
            Ok(a) => Ok(a),
            Err(vk) => request(Some(wgpu::Backends::GL))
                .map_err(|gl| GpuError::NoAdapter(format!("Vulkan: {vk}; GL: {gl}"))),
        }
    }
}

fn adapter_name(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {})", info.name, info.backend, info.driver_info)
}

/// The adapter a [`crate::GpuVoxelizer`] would run on, found without creating a device or
/// compiling a shader.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AdapterProbe {
    /// Name, backend and driver, as [`crate::GpuVoxelizer::adapter_name`] gives them.
    pub name: String,
    /// A CPU-emulated device (lavapipe, llvmpipe, WARP): correct but slower than the CPU
    /// voxelizer, so `--backend auto` does not pick it.
    pub software: bool,
}

/// Finds the adapter [`crate::GpuVoxelizer::new`] would open, without opening it: what
/// `--backend auto` needs to decide. On a machine without a GPU this costs the Vulkan
/// instance and adapter enumeration only (tens of milliseconds on lavapipe), not the device and
/// pipeline creation (half a second of shader compilation by llvmpipe).
pub fn probe_adapter() -> Result<AdapterProbe, GpuError> {
    let info = find_adapter()?.get_info();
    Ok(AdapterProbe {
        name: adapter_name(&info),
        software: info.device_type == wgpu::DeviceType::Cpu,
    })
}

/// The voxelizer's device: `SHADER_F64` where the adapter has it.
pub(crate) fn open() -> Result<Gpu, GpuError> {
    open_device("voxlod-gpu", wgpu::Features::SHADER_F64)
}

/// Opens a device on the adapter [`probe_adapter`] names, with those of the `wanted`
/// features the adapter has and the adapter's own limits, and with uncaptured errors kept
/// for [`Gpu::check`] instead of panicking.
pub fn open_device(label: &str, wanted: wgpu::Features) -> Result<Gpu, GpuError> {
    device_on(find_adapter()?, label, wanted)
}

/// [`open_device`] on an adapter of `instance` that can present to `surface` (a window).
pub fn open_device_for_surface(
    instance: &wgpu::Instance,
    surface: &wgpu::Surface,
    label: &str,
    wanted: wgpu::Features,
) -> Result<Gpu, GpuError> {
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: Some(surface),
        ..Default::default()
    }))
    .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
    device_on(adapter, label, wanted)
}

/// The device on `adapter`: the `wanted` features it has, its own limits, errors captured.
fn device_on(adapter: wgpu::Adapter, label: &str, wanted: wgpu::Features) -> Result<Gpu, GpuError> {
    let info = adapter.get_info();
    let name = adapter_name(&info);
    let features = wanted & adapter.features();
    let limits = adapter.limits();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some(label),
        required_features: features,
        required_limits: limits.clone(),
        experimental_features: wgpu::ExperimentalFeatures::disabled(),
        memory_hints: wgpu::MemoryHints::Performance,
        trace: wgpu::Trace::Off,
    }))
    .map_err(|e| GpuError::Device {
        adapter: name.clone(),
        reason: e.to_string(),
    })?;
    let error = Arc::new(Mutex::new(None::<String>));
    let sink = error.clone();
    device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
        if let Ok(mut slot) = sink.lock() {
            slot.get_or_insert_with(|| e.to_string());
        }
    }));
    Ok(Gpu {
        device,
        queue,
        name,
        f64: features.contains(wgpu::Features::SHADER_F64),
        info: info.clone(),
        adapter,
        software: info.device_type == wgpu::DeviceType::Cpu,
        limits,
        error,
    })
}

impl Gpu {
    /// Fails with the first error the device reported since the last check.
    pub fn check(&self) -> Result<(), GpuError> {
        let e = self.error.lock().ok().and_then(|mut s| s.take());
        match e {
            Some(reason) => Err(GpuError::Wgpu {
                adapter: self.name.clone(),
                reason,
            }),
            None => Ok(()),
        }
    }

    /// Waits for all submitted work.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback {
                adapter: self.name.clone(),
                reason: e.to_string(),
            })?;
        self.check()
    }

    /// Waits until submission `idx` has finished.
    pub fn wait_for(&self, idx: wgpu::SubmissionIndex) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(idx),
                timeout: None,
            })
            .map_err(|e| GpuError::Readback {
                adapter: self.name.clone(),
                reason: e.to_string(),
            })?;
        self.check()
    }

    /// Copies `size` bytes of `src` into `staging` (MAP_READ) and returns them.
    pub fn read(
        &self,
        src: &wgpu::Buffer,
        staging: &wgpu::Buffer,
        size: u64,
    ) -> Result<Vec<u8>, GpuError> {
        debug_assert!(size <= staging.size() && size <= src.size());
        if size == 0 {
            return Ok(Vec::new());
        }
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(src, 0, staging, 0, size);
        self.queue.submit([enc.finish()]);
        self.map_staging(staging, size)
    }

    /// Maps the first `size` bytes of `staging` after all submitted work and returns them.
    pub fn map_staging(&self, staging: &wgpu::Buffer, size: u64) -> Result<Vec<u8>, GpuError> {
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, 0..size, move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        let fail = |reason: String| GpuError::Readback {
            adapter: self.name.clone(),
            reason,
        };
        rx.recv()
            .map_err(|e| fail(e.to_string()))?
            .map_err(|e| fail(e.to_string()))?;
        let out = {
            let view = staging
                .get_mapped_range(0..size)
                .map_err(|e| fail(e.to_string()))?;
            view.to_vec()
        };
        staging.unmap();
        Ok(out)
    }
}
