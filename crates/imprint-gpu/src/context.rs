//! The device, its limits, and the buffer/pipeline helpers every stage shares.

use imprint_core::error::human_bytes;
use imprint_core::{Error, Result};
use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::sync::{Mutex, OnceLock};
use wgpu::util::DeviceExt;

/// Threads per workgroup of every 1D dispatch ([`GpuContext::dispatch_1d`]); the WGSL side
/// uses the same number (`shaders/common/dispatch.wgsl`).
pub const WORKGROUP_SIZE: u32 = 64;

const NO_ADAPTER: &str = "no GPU adapter found; install a Vulkan driver \
    (Debian: mesa-vulkan-drivers libvulkan1) or use --backend cpu";

/// The device's queue, through which every queued upload is counted
/// ([`crate::transfer`]): the writes of `wgpu::Queue`, each adding its bytes to this thread's
/// uploads, and submission. There is no way to the bare `wgpu::Queue`, so no upload can miss
/// the counters.
pub struct GpuQueue {
    inner: wgpu::Queue,
}

impl GpuQueue {
    /// `wgpu::Queue::write_buffer`, counted: `data.len()` bytes uploaded.
    pub fn write_buffer(&self, buffer: &wgpu::Buffer, offset: wgpu::BufferAddress, data: &[u8]) {
        crate::transfer::count_upload(data.len() as u64);
        self.inner.write_buffer(buffer, offset, data);
    }

    /// `wgpu::Queue::write_texture`, counted: `data.len()` bytes uploaded.
    pub fn write_texture(
        &self,
        texture: wgpu::TexelCopyTextureInfo<'_>,
        data: &[u8],
        data_layout: wgpu::TexelCopyBufferLayout,
        size: wgpu::Extent3d,
    ) {
        crate::transfer::count_upload(data.len() as u64);
        self.inner.write_texture(texture, data, data_layout, size);
    }

    /// `wgpu::Queue::submit` (moves nothing between host and device).
    pub fn submit<I: IntoIterator<Item = wgpu::CommandBuffer>>(
        &self,
        command_buffers: I,
    ) -> wgpu::SubmissionIndex {
        self.inner.submit(command_buffers)
    }

    /// The bare queue, for code that is not a stage and must hand it to a library (the
    /// viewer's UI renderer): what goes through it is not counted.
    pub fn uncounted(&self) -> &wgpu::Queue {
        &self.inner
    }

    /// `wgpu::Queue::get_timestamp_period`.
    pub fn get_timestamp_period(&self) -> f32 {
        self.inner.get_timestamp_period()
    }
}

impl std::fmt::Debug for GpuQueue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("GpuQueue")
    }
}

/// One wgpu device and queue, with what the stages need to know about them.
pub struct GpuContext {
    /// The instance and adapter the device came from (a window's surface is made with them).
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    /// The queue: its writes are counted uploads ([`crate::transfer`]).
    pub queue: GpuQueue,
    pub adapter_info: wgpu::AdapterInfo,
    /// The limits the device was created with (all the adapter offers).
    pub limits: wgpu::Limits,
    pub features: wgpu::Features,
    /// Compiled pipelines by (source, entry point): shader compilation is slow (very slow on
    /// a software rasteriser), and stages run every frame.
    pipelines: Mutex<HashMap<u64, wgpu::ComputePipeline>>,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.adapter_info.name)
            .field("backend", &self.adapter_info.backend)
            .field("device_type", &self.adapter_info.device_type)
            .finish_non_exhaustive()
    }
}

/// Preference order of adapter kinds: hardware first; a CPU (software) adapter is accepted
/// last so that tests and CI without a GPU still run the GPU path.
fn rank(t: wgpu::DeviceType) -> u32 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

impl GpuContext {
    /// The process-wide context, created on first use. One device per process: devices are
    /// expensive, and resources of one device cannot be used on another. A failure is
    /// remembered, so a machine without a GPU answers quickly every time.
    pub fn shared() -> Result<&'static GpuContext> {
        static SHARED: OnceLock<std::result::Result<GpuContext, String>> = OnceLock::new();
        SHARED
            .get_or_init(|| {
                GpuContext::new().map_err(|e| match e {
                    Error::Gpu(msg) => msg,
                    other => other.to_string(),
                })
            })
            .as_ref()
            .map_err(|msg| Error::Gpu(msg.clone()))
    }

    /// A fresh context (prefer [`GpuContext::shared`]). Backends can be narrowed with the
    /// usual `WGPU_BACKEND` environment variable.
    pub fn new() -> Result<Self> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        let adapter = adapters
            .into_iter()
            .filter(|a| {
                a.get_downlevel_capabilities()
                    .flags
                    .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
            })
            .min_by_key(|a| {
                let info = a.get_info();
                // Vulkan first among equals: it is the backend the project tests on.
                (
                    rank(info.device_type),
                    info.backend != wgpu::Backend::Vulkan,
                )
            })
            .ok_or_else(|| Error::Gpu(NO_ADAPTER.into()))?;
        let adapter_info = adapter.get_info();
        tracing::info!(
            "GPU adapter: {} ({:?}, {:?})",
            adapter_info.name,
            adapter_info.backend,
            adapter_info.device_type
        );
        let limits = adapter.limits();
        // Timestamps are optional: only for timing, never for results.
        let features = adapter.features() & wgpu::Features::TIMESTAMP_QUERY;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("imprint"),
            required_features: features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| {
            Error::Gpu(format!(
                "adapter '{}' refused a device: {e}",
                adapter_info.name
            ))
        })?;
        Ok(GpuContext {
            instance,
            adapter,
            device,
            queue: GpuQueue { inner: queue },
            adapter_info,
            limits,
            features,
            pipelines: Mutex::new(HashMap::new()),
        })
    }

    /// A software rasteriser (Mesa lavapipe/llvmpipe, WARP, SwiftShader): correct but slow, so
    /// `backend: Auto` does not choose it.
    pub fn is_software(&self) -> bool {
        self.adapter_info.device_type == wgpu::DeviceType::Cpu
    }

    /// "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)"-style name for logs and reports.
    pub fn adapter_name(&self) -> String {
        format!(
            "{} ({:?})",
            self.adapter_info.name, self.adapter_info.backend
        )
    }

    pub fn has_timestamps(&self) -> bool {
        self.features.contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// The largest single buffer a shader can bind as storage on this device.
    pub fn max_storage_bytes(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
    }

    /// Refuses, before allocating, a storage buffer of `bytes` that this device cannot bind,
    /// with a message that names what it was for. (wgpu would otherwise panic on validation.)
    pub fn check_storage(&self, what: &str, bytes: u64) -> Result<()> {
        let limit = self.max_storage_bytes();
        if bytes > limit {
            return Err(Error::TooLarge {
                what: format!(
                    "{what} (one GPU storage buffer; {} binds at most {})",
                    self.adapter_name(),
                    human_bytes(limit)
                ),
                needed: bytes,
                available: limit,
            });
        }
        Ok(())
    }

    /// Refuses a grid of `cells` cells whose per-cell buffer of `bytes_per_cell` does not fit
    /// one storage binding, or whose cell indices do not fit the u32 the shaders use (with
    /// u32::MAX kept free as the "none" marker).
    pub fn check_grid(&self, what: &str, dims: [u32; 3], bytes_per_cell: u64) -> Result<()> {
        let cells = dims.iter().map(|&d| d as u64).product::<u64>();
        let what = format!("{what} on a {}x{}x{} grid", dims[0], dims[1], dims[2]);
        if cells >= u32::MAX as u64 {
            return Err(Error::TooLarge {
                what: format!("{what} (GPU cell indices are 32-bit)"),
                needed: cells.saturating_mul(bytes_per_cell),
                available: (u32::MAX as u64 - 1) * bytes_per_cell,
            });
        }
        self.check_storage(&what, cells * bytes_per_cell)
    }

    /// Creates a buffer inside an out-of-memory error scope, so a failed allocation is an
    /// error and not a panic.
    fn guarded<T>(&self, label: &str, bytes: u64, make: impl FnOnce() -> T) -> Result<T> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let value = make();
        match pollster::block_on(scope.pop()) {
            None => Ok(value),
            Some(e) => Err(Error::Gpu(format!(
                "could not allocate {label} ({}) on {}: {e}",
                human_bytes(bytes),
                self.adapter_name()
            ))),
        }
    }

    /// A storage buffer holding `data` (readable back, writable by the queue).
    pub fn storage_buffer<T: bytemuck::Pod>(
        &self,
        label: &str,
        data: &[T],
    ) -> Result<wgpu::Buffer> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        self.check_storage(label, bytes.len() as u64)?;
        // A zero-sized binding is invalid; an empty array becomes one zeroed word.
        let padded;
        let contents = if bytes.is_empty() {
            padded = [0u8; 16];
            &padded[..]
        } else {
            bytes
        };
        crate::transfer::count_upload(contents.len() as u64);
        self.guarded(label, contents.len() as u64, || {
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents,
                    usage: wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::COPY_SRC
                        | wgpu::BufferUsages::COPY_DST,
                })
        })
    }

    /// A zero-filled storage buffer of `bytes` (rounded up to a multiple of 4, at least 16),
    /// readable back and writable by the queue.
    pub fn zeroed_buffer(&self, label: &str, bytes: u64) -> Result<wgpu::Buffer> {
        self.buffer(label, bytes, wgpu::BufferUsages::empty())
    }

    /// [`GpuContext::zeroed_buffer`] with extra usages (e.g. `INDIRECT` for dispatch arguments
    /// a shader writes).
    pub fn buffer(
        &self,
        label: &str,
        bytes: u64,
        extra: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer> {
        self.check_storage(label, bytes)?;
        let size = bytes.max(16).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        self.guarded(label, size, || {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST
                    | extra,
                mapped_at_creation: false,
            })
        })
    }

    /// A small uniform buffer holding `value` (parameters of a pass).
    pub fn uniform_buffer<T: bytemuck::Pod>(&self, label: &str, value: &T) -> wgpu::Buffer {
        crate::transfer::count_upload(std::mem::size_of::<T>() as u64);
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::bytes_of(value),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// Copies a buffer (made with `COPY_SRC`, as all of ours are) back to the CPU, waiting for
    /// the queue. For writers, tests, error measurement and CPU consumers: GPU results
    /// otherwise stay on the GPU. Counted ([`crate::transfer`]): the buffer's whole size.
    pub fn read_buffer<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer) -> Result<Vec<T>> {
        let size = buffer.size();
        let staging = self.guarded("readback buffer", size, || {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("imprint readback"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })?;
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        let bytes = self.map_read(&staging, 0..size, "a buffer")?;
        let whole = (bytes.len() / std::mem::size_of::<T>().max(1)) * std::mem::size_of::<T>();
        Ok(bytemuck::pod_collect_to_vec::<u8, T>(&bytes[..whole]))
    }

    /// Waits for the queue, maps `range` of `staging` (a `MAP_READ` buffer the submitted work
    /// filled), copies it out and unmaps: the one place a buffer is mapped, so every
    /// read-back is counted ([`crate::transfer`]: `range`'s length).
    pub(crate) fn map_read(
        &self,
        staging: &wgpu::Buffer,
        range: std::ops::Range<u64>,
        what: &str,
    ) -> Result<Vec<u8>> {
        crate::transfer::count_read_back(range.end - range.start);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, range.clone(), move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv()
            .map_err(|_| Error::Gpu(format!("read-back of {what} was never completed")))?
            .map_err(|e| Error::Gpu(format!("could not map {what} for reading: {e}")))?;
        let out = {
            let view = staging
                .get_mapped_range(range)
                .map_err(|e| Error::Gpu(format!("could not read {what} (mapped): {e}")))?;
            view.to_vec()
        };
        staging.unmap();
        Ok(out)
    }

    /// Blocks until all submitted work is done.
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| Error::Gpu(format!("waiting for the GPU failed: {e}")))
    }

    /// A compute pipeline for `entry` of the WGSL made by concatenating `sources` (WGSL has no
    /// `#include`: shared helpers from `shaders/common/` are prepended this way). Cached, so
    /// calling it every frame costs a hash. Shader errors come back as [`Error::Gpu`] with
    /// naga's message (which names the line).
    pub fn pipeline(
        &self,
        label: &str,
        sources: &[&str],
        entry: &str,
    ) -> Result<wgpu::ComputePipeline> {
        let source = sources.join("\n");
        let key = {
            let mut h = std::collections::hash_map::DefaultHasher::new();
            source.hash(&mut h);
            entry.hash(&mut h);
            h.finish()
        };
        if let Some(p) = self
            .pipelines
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
        {
            return Ok(p.clone());
        }
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = self
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
        let pipeline = self
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Gpu(format!("shader '{label}' entry '{entry}': {e}")));
        }
        self.pipelines
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, pipeline.clone());
        Ok(pipeline)
    }

    /// A bind group for group 0 of `pipeline` (its layout derived from the shader), binding
    /// each buffer whole at the given binding number.
    pub fn bind_group(
        &self,
        label: &str,
        pipeline: &wgpu::ComputePipeline,
        buffers: &[(u32, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .map(|&(binding, buffer)| wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        })
    }

    /// Dispatches enough workgroups of [`WORKGROUP_SIZE`] for `threads` threads, folding the
    /// count into x and y when it exceeds the per-dimension limit (65535 groups = 4M threads).
    /// The shader recovers the thread index with `thread_index()` from
    /// `shaders/common/dispatch.wgsl` and must ignore indices >= `threads`.
    pub fn dispatch_1d(&self, pass: &mut wgpu::ComputePass<'_>, threads: u32) {
        let groups = threads.div_ceil(WORKGROUP_SIZE).max(1);
        let max = self.limits.max_compute_workgroups_per_dimension.max(1);
        let x = groups.min(max);
        let y = groups.div_ceil(x);
        pass.dispatch_workgroups(x, y, 1);
    }

    /// Records a pass that sets every u32 of `buffer` to `value` (atomicMin targets start at
    /// u32::MAX; `clear_buffer` only writes zeros).
    pub fn fill_u32(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        buffer: &wgpu::Buffer,
        value: u32,
    ) -> Result<()> {
        #[repr(C)]
        #[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
        struct Fill {
            value: u32,
            count: u32,
            _pad: [u32; 2],
        }
        let count = u32::try_from(buffer.size() / 4)
            .map_err(|_| Error::Gpu("buffer too large to fill with 32-bit indices".into()))?;
        let pipeline = self.pipeline(
            "fill_u32",
            &[
                crate::shader!("common/dispatch.wgsl"),
                crate::shader!("common/fill.wgsl"),
            ],
            "fill_u32",
        )?;
        let params = self.uniform_buffer(
            "fill params",
            &Fill {
                value,
                count,
                _pad: [0; 2],
            },
        );
        let bind = self.bind_group("fill", &pipeline, &[(0, &params), (1, buffer)]);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("fill_u32"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        self.dispatch_1d(&mut pass, count);
        Ok(())
    }
}
