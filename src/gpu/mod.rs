//! The GPU side of penumbra: one `GpuContext` (instance, adapter, device, queue) that lives
//! as long as the process, and the pools, timers and readback helpers built on it. Only this
//! module and the passes it serves create GPU objects.

pub mod layout;
pub mod pool;
pub mod readback;
pub mod scene;
pub mod shaders;
pub mod timing;

use std::fmt;

use serde::Serialize;

/// Which kind of Vulkan adapter to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum AdapterChoice {
    /// A hardware GPU when there is one, else a software rasteriser (lavapipe).
    #[default]
    Auto,
    /// Only a hardware GPU (discrete, integrated or virtual).
    Hardware,
    /// Only a software adapter (Mesa's lavapipe / llvmpipe).
    Software,
}

impl fmt::Display for AdapterChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            AdapterChoice::Auto => "auto",
            AdapterChoice::Hardware => "hardware",
            AdapterChoice::Software => "software",
        })
    }
}

/// What the adapter is, as logged at start-up and reported by `/v1/stats`.
#[derive(Debug, Clone, Serialize)]
pub struct AdapterSummary {
    pub name: String,
    pub backend: String,
    pub device_type: String,
    pub driver: String,
    pub driver_info: String,
    pub timestamps: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no {0} Vulkan adapter found (on a machine without a GPU, install Mesa's lavapipe: `apt-get install mesa-vulkan-drivers`)")]
    NoAdapter(AdapterChoice),
    #[error("the adapter refused to create a device: {0}")]
    RequestDevice(#[from] wgpu::RequestDeviceError),
    /// The device is gone (a driver reset, a removed GPU): the engine opens a new one.
    #[error("the GPU device was lost")]
    Lost,
    /// Waiting for the GPU failed.
    #[error("waiting for the GPU failed: {0}")]
    Poll(String),
    /// A buffer could not be mapped for reading.
    #[error("a GPU buffer could not be read back: {0}")]
    Map(String),
}

/// A GPU failure while rendering fails that one job, with a generic message towards its
/// client (the details are logged where the error becomes a response).
impl From<GpuError> for crate::error::JobError {
    fn from(error: GpuError) -> Self {
        crate::error::JobError::internal(format!("the renderer failed on the GPU: {error}"))
    }
}

/// Device, queue and what we learned about the adapter. Lives until the device is lost; the
/// engine then opens a new one with the same `choice` (see `Engine::recover_device`).
pub struct GpuContext {
    /// The adapter choice this context was opened with, to open its replacement.
    pub choice: AdapterChoice,
    /// Set by wgpu's device-lost callback (driver reset, removal, or `destroy`).
    lost: std::sync::Arc<std::sync::atomic::AtomicBool>,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: AdapterSummary,
    pub limits: wgpu::Limits,
    /// A software rasteriser (lavapipe): a workgroup runs as a loop over SIMD groups of 8
    /// lanes on a CPU core, so passes that do little per invocation size their workgroups
    /// for it (see the wedges rasteriser).
    pub software: bool,
    /// Whether passes can be timed with GPU timestamp queries.
    pub timestamps: bool,
    /// Whether timestamps can also be written between a pass's dispatches, so each dispatch
    /// is timed on its own (`GpuTimer::mark`), and around copies recorded on an encoder
    /// (`GpuTimer::time_encoder`).
    pub timestamps_inside_passes: bool,
    /// Set by `fail_next_readback` (fault tests).
    fail_next_readback: std::sync::atomic::AtomicBool,
}

/// The adapter `choice` allows, the fastest kind first (a discrete GPU before an integrated
/// one, any GPU before a software rasteriser).
fn pick_adapter(adapters: Vec<wgpu::Adapter>, choice: AdapterChoice) -> Result<wgpu::Adapter, GpuError> {
    let rank = |t: wgpu::DeviceType| match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    };
    adapters
        .into_iter()
        .filter(|a| {
            let software = a.get_info().device_type == wgpu::DeviceType::Cpu;
            match choice {
                AdapterChoice::Auto => true,
                AdapterChoice::Hardware => !software,
                AdapterChoice::Software => software,
            }
        })
        .min_by_key(|a| rank(a.get_info().device_type))
        .ok_or(GpuError::NoAdapter(choice))
}

impl GpuContext {
    /// Opens the preferred Vulkan adapter headless. Blocks; call it once at start-up.
    pub fn new(choice: AdapterChoice) -> Result<Self, GpuError> {
        pollster::block_on(Self::new_async(choice))
    }

    async fn new_async(choice: AdapterChoice) -> Result<Self, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::VULKAN,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let adapter = pick_adapter(instance.enumerate_adapters(wgpu::Backends::VULKAN).await, choice)?;
        let info = adapter.get_info();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let inside = wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
        let timestamps_inside_passes = timestamps && adapter.features().contains(inside);
        let mut required_features = wgpu::Features::empty();
        if timestamps {
            required_features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        if timestamps_inside_passes {
            required_features |= inside;
        }
        // Ask for what the adapter has: large shadow maps and outputs need more than the
        // WebGPU defaults, and penumbra enforces its own (smaller) limits per job.
        let limits = adapter.limits();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("GpuContext::device"),
                required_features,
                required_limits: limits.clone(),
                ..Default::default()
            })
            .await?;
        // wgpu's default handler panics; an error outside an error scope is a bug in
        // penumbra, to be logged, not a reason to take every other job down.
        device.on_uncaptured_error(std::sync::Arc::new(|error: wgpu::Error| {
            tracing::error!(%error, "uncaptured GPU error");
        }));
        let lost = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = lost.clone();
        device.set_device_lost_callback(move |reason, message| {
            tracing::error!(?reason, %message, "GPU device lost");
            flag.store(true, std::sync::atomic::Ordering::SeqCst);
        });
        let software = info.device_type == wgpu::DeviceType::Cpu;
        let adapter = AdapterSummary {
            name: info.name,
            backend: format!("{:?}", info.backend).to_lowercase(),
            device_type: format!("{:?}", info.device_type),
            driver: info.driver,
            driver_info: info.driver_info,
            timestamps,
        };
        Ok(Self {
            choice,
            lost,
            device,
            queue,
            adapter,
            limits,
            software,
            timestamps,
            timestamps_inside_passes,
            fail_next_readback: Default::default(),
        })
    }

    /// Whether the device is gone: every later submission would fail or read back nothing.
    pub fn is_lost(&self) -> bool {
        self.lost.load(std::sync::atomic::Ordering::SeqCst)
    }

    /// Destroys the device as a driver reset would, for the fault tests of device-loss
    /// recovery. Not for production paths.
    #[doc(hidden)]
    pub fn simulate_loss(&self) {
        self.device.destroy();
        // wgpu calls the lost callback on destroy; set the flag too in case a backend defers it.
        self.lost.store(true, std::sync::atomic::Ordering::SeqCst);
    }

    /// Makes the next readback fail as a failed buffer map would, for the fault test that a
    /// GPU error fails one job and nothing else. Not for production paths.
    #[doc(hidden)]
    pub fn fail_next_readback(&self) {
        self.fail_next_readback.store(true, std::sync::atomic::Ordering::SeqCst);
    }

    /// Submits what `encoder` recorded and blocks until the GPU has run it (and everything
    /// before it).
    pub fn submit_and_wait(&self, encoder: wgpu::CommandEncoder) -> Result<(), GpuError> {
        self.queue.submit([encoder.finish()]);
        self.wait_idle()
    }

    /// Blocks until the GPU has finished everything submitted so far.
    pub fn wait_idle(&self) -> Result<(), GpuError> {
        let polled = self.device.poll(wgpu::PollType::wait_indefinitely());
        if self.is_lost() {
            return Err(GpuError::Lost);
        }
        polled.map(drop).map_err(|e| GpuError::Poll(e.to_string()))
    }

    /// Maps `slices` for reading and waits for the GPU; fails when a map reported an error.
    /// A map whose callback has not run yet (another thread's poll may be running it) is not
    /// an error here: reading the mapped range then says whether it is mapped.
    pub fn map_for_reading(&self, slices: &[wgpu::BufferSlice<'_>]) -> Result<(), GpuError> {
        type Outcome = std::sync::Arc<std::sync::Mutex<Option<Result<(), wgpu::BufferAsyncError>>>>;
        let outcomes: Vec<Outcome> = slices.iter().map(|_| Default::default()).collect();
        for (slice, outcome) in slices.iter().zip(&outcomes) {
            let outcome = outcome.clone();
            slice.map_async(wgpu::MapMode::Read, move |result| *outcome.lock().unwrap_or_else(|p| p.into_inner()) = Some(result));
        }
        self.wait_idle()?;
        if self.fail_next_readback.swap(false, std::sync::atomic::Ordering::SeqCst) {
            return Err(GpuError::Map("injected readback failure".into()));
        }
        for outcome in &outcomes {
            if let Some(Err(error)) = outcome.lock().unwrap_or_else(|p| p.into_inner()).take() {
                return Err(GpuError::Map(error.to_string()));
            }
        }
        Ok(())
    }
}
