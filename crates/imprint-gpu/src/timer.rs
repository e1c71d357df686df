//! Timing GPU work: per-pass timestamps where the adapter supports `TIMESTAMP_QUERY`, and the
//! wall clock from submit to completion always (the fallback, and a check on the former).
//! Only for reports and benches: results never depend on it.

use crate::GpuContext;
use imprint_core::{Error, Result};
use std::time::{Duration, Instant};

/// Timings of one submission.
#[derive(Clone, Debug, Default)]
pub struct Timings {
    /// GPU time of each timed pass, in recording order (empty without timestamps).
    pub passes: Vec<(String, Duration)>,
    /// Submit to completion, measured on the CPU around `device.poll(wait)`.
    pub wall: Duration,
}

impl Timings {
    /// Sum of the timed passes, or None without timestamp support.
    pub fn gpu(&self) -> Option<Duration> {
        (!self.passes.is_empty()).then(|| self.passes.iter().map(|(_, d)| *d).sum())
    }

    /// The best measure available: GPU time when known, else wall time.
    pub fn best(&self) -> Duration {
        self.gpu().unwrap_or(self.wall)
    }
}

struct Queries {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    readback: wgpu::Buffer,
}

/// Collects timestamps for the passes of one (or several) command encoders, then one
/// [`GpuTimer::submit`] and [`GpuTimer::wait`]. Use [`compute_pass`] to begin passes so that
/// code with and without a timer is the same.
pub struct GpuTimer {
    queries: Option<Queries>,
    labels: Vec<String>,
    period_ns: f64,
    submitted: Option<Instant>,
}

impl GpuTimer {
    /// Passes one timer can time (two timestamps each).
    pub const MAX_PASSES: u32 = 64;

    pub fn new(ctx: &GpuContext) -> Self {
        let queries = ctx.has_timestamps().then(|| {
            let count = 2 * Self::MAX_PASSES;
            let bytes = count as u64 * 8;
            Queries {
                set: ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("imprint timer"),
                    ty: wgpu::QueryType::Timestamp,
                    count,
                }),
                resolve: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timer resolve"),
                    size: bytes,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                readback: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timer readback"),
                    size: bytes,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
            }
        });
        GpuTimer {
            queries,
            labels: Vec::new(),
            period_ns: ctx.queue.get_timestamp_period() as f64,
            submitted: None,
        }
    }

    pub fn has_timestamps(&self) -> bool {
        self.queries.is_some()
    }

    /// Submits `encoder` (after resolving the timestamps into it) and starts the wall clock.
    pub fn submit(&mut self, ctx: &GpuContext, mut encoder: wgpu::CommandEncoder) {
        if let Some(q) = &self.queries {
            let n = 2 * self.labels.len() as u32;
            if n > 0 {
                encoder.resolve_query_set(&q.set, 0..n, &q.resolve, 0);
                encoder.copy_buffer_to_buffer(&q.resolve, 0, &q.readback, 0, n as u64 * 8);
            }
        }
        self.submitted = Some(Instant::now());
        ctx.queue.submit([encoder.finish()]);
    }

    /// Waits for the submitted work and returns its timings; the timer is then reset.
    pub fn wait(&mut self, ctx: &GpuContext) -> Result<Timings> {
        let start = self
            .submitted
            .take()
            .ok_or_else(|| Error::Gpu("GpuTimer::wait without a submit".into()))?;
        ctx.wait()?;
        let wall = start.elapsed();
        let labels = std::mem::take(&mut self.labels);
        let mut passes = Vec::new();
        if let (Some(q), false) = (&self.queries, labels.is_empty()) {
            let bytes = labels.len() as u64 * 16;
            let raw = ctx.map_read(&q.readback, 0..bytes, "timestamps")?;
            let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&raw);
            for (i, label) in labels.into_iter().enumerate() {
                let dt = ticks[2 * i + 1].saturating_sub(ticks[2 * i]);
                passes.push((
                    label,
                    Duration::from_nanos((dt as f64 * self.period_ns) as u64),
                ));
            }
        }
        Ok(Timings { passes, wall })
    }

    /// Timestamp writes for the next pass, or None when out of queries or unsupported.
    fn next_writes(&mut self, label: &str) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let q = self.queries.as_ref()?;
        let i = self.labels.len() as u32;
        if i >= Self::MAX_PASSES {
            return None;
        }
        self.labels.push(label.to_string());
        Some(wgpu::ComputePassTimestampWrites {
            query_set: &q.set,
            beginning_of_pass_write_index: Some(2 * i),
            end_of_pass_write_index: Some(2 * i + 1),
        })
    }
}

/// Begins a compute pass, timed when a timer is given (and the adapter has timestamps).
pub fn compute_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    timer: Option<&mut GpuTimer>,
) -> wgpu::ComputePass<'e> {
    let timestamp_writes = timer.and_then(|t| t.next_writes(label));
    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes,
    })
}

/// How a recorded pass is sized.
pub enum Dispatch<'a> {
    /// One invocation per item (folded into x and y past the per-dimension limit).
    Threads(u32),
    /// Explicit workgroup counts.
    Groups(u32, u32, u32),
    /// Workgroup counts a previous pass wrote into this buffer (x, y, z as u32).
    Indirect(&'a wgpu::Buffer),
}

/// Records one compute pass: `pipeline` with `buffers` bound to group 0, sized by `dispatch`,
/// timed when a timer is given. Every stage records its passes this way.
pub fn record_pass(
    ctx: &GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    buffers: &[(u32, &wgpu::Buffer)],
    dispatch: Dispatch<'_>,
    timer: Option<&mut GpuTimer>,
) {
    let bind = ctx.bind_group(label, pipeline, buffers);
    let mut pass = compute_pass(encoder, label, timer);
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, &bind, &[]);
    match dispatch {
        Dispatch::Threads(n) => ctx.dispatch_1d(&mut pass, n),
        Dispatch::Groups(x, y, z) => pass.dispatch_workgroups(x, y, z),
        Dispatch::Indirect(args) => pass.dispatch_workgroups_indirect(args, 0),
    }
}

/// Submits `encoder`, through the timer when there is one (it resolves its queries).
pub fn submit(ctx: &GpuContext, encoder: wgpu::CommandEncoder, timer: Option<&mut GpuTimer>) {
    match timer {
        Some(t) => t.submit(ctx, encoder),
        None => {
            ctx.queue.submit([encoder.finish()]);
        }
    }
}
