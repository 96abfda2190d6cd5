//! The WGSL evaluator: one GPU context per process (instance, adapter, device, queue and
//! the three compute pipelines of `shaders/meridian.wgsl`, compiled once), and
//! evaluators that keep their storage and staging buffers across iterations, growing
//! them only when a larger cloud or batch arrives.

use super::{
    Candidate, Cost, EvalError, Evaluator, Loss, NUM_PARAMS, NUM_UPPER, NormalEquations, PointSet,
    check_sets,
};
use std::sync::{Arc, Mutex, OnceLock};

/// The kernel source, checked by naga in the tests and compiled by wgpu at start-up.
pub const SHADER_SOURCE: &str = include_str!("../../shaders/meridian.wgsl");

/// Workgroup size of the reduction kernels (`WG` in the shader).
const WG: u32 = 32;
/// Values per (candidate, workgroup) partial of the normal-equation kernel (`NE`).
const NE: usize = NUM_UPPER + NUM_PARAMS + 2;
/// Output stride of one partial: NE values and the completion marker.
const NE_OUT: usize = NE + 1;
/// Output stride of one cost partial: cost, count, completion marker.
const COST_OUT: usize = 3;
/// Most points one invocation loops over. lavapipe was seen to drop dispatches whose
/// invocations looped over about a thousand points each, returning nothing; more
/// workgroups keep every invocation short (and the completion markers catch the rest).
const MAX_POINTS_PER_INVOCATION: usize = 256;
/// Workgroup size of the residual kernel.
const WG_RESIDUALS: u32 = 64;

/// Which adapter to take.
#[derive(Clone, Debug, Default)]
pub struct AdapterChoice {
    /// Only adapters whose name contains this (case-insensitive), e.g. "nvidia" or "llvmpipe".
    pub name_filter: Option<String>,
}

impl AdapterChoice {
    /// From `SUPERTOROID_ADAPTER` (a name filter), if set.
    pub fn from_env() -> Self {
        Self {
            name_filter: std::env::var("SUPERTOROID_ADAPTER")
                .ok()
                .filter(|s| !s.is_empty()),
        }
    }
}

/// The process-wide GPU state.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    layout: wgpu::BindGroupLayout,
    residuals: wgpu::ComputePipeline,
    normal_equations: wgpu::ComputePipeline,
    costs: wgpu::ComputePipeline,
    /// Set by the uncaptured-error handler; a failed context is not used again.
    failure: Arc<Mutex<Option<String>>>,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n_points: u32,
    n_candidates: u32,
    loss: u32,
    groups_x: u32,
    loss_scale: f32,
    _pad: [f32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuCandidate {
    columns: [[f32; 4]; 3],
    translation: [f32; 4],
    sizes: [f32; 4],
    exponents: [f32; 2],
    /// first point and number of points of the candidate's set
    range: [u32; 2],
}

impl GpuCandidate {
    fn from(c: &Candidate, range: (u32, u32)) -> Self {
        let r = c.pose.matrix();
        let col = |v: glam::DVec3| [v.x as f32, v.y as f32, v.z as f32, 0.0];
        let s = c.shape;
        Self {
            columns: [col(r.x_axis), col(r.y_axis), col(r.z_axis)],
            translation: col(c.pose.translation),
            sizes: [s.a1 as f32, s.a2 as f32, s.a3 as f32, s.a4 as f32],
            exponents: [s.eps1 as f32, s.eps2 as f32],
            range: [range.0, range.1],
        }
    }
}

fn rank(t: wgpu::DeviceType) -> u32 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    }
}

static SHARED: OnceLock<Result<Arc<GpuContext>, String>> = OnceLock::new();

impl GpuContext {
    /// The process's one context, created on first use with `choice`.
    pub fn shared(choice: &AdapterChoice) -> Result<Arc<GpuContext>, EvalError> {
        SHARED
            .get_or_init(|| {
                GpuContext::new(choice)
                    .map(Arc::new)
                    .map_err(|e| e.to_string())
            })
            .clone()
            .map_err(EvalError::NoAdapter)
    }

    /// Picks an adapter (real GPUs before software ones such as lavapipe; `WGPU_BACKEND`
    /// narrows the backends), opens a device with the adapter's own limits and compiles
    /// the pipelines.
    pub fn new(choice: &AdapterChoice) -> Result<Self, EvalError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
        let mut adapters = pollster::block_on(instance.enumerate_adapters(backends));
        if let Some(filter) = &choice.name_filter {
            let f = filter.to_ascii_lowercase();
            adapters.retain(|a| a.get_info().name.to_ascii_lowercase().contains(&f));
        }
        adapters.sort_by_key(|a| rank(a.get_info().device_type));
        let adapter = adapters.into_iter().next().ok_or_else(|| {
            EvalError::NoAdapter(match &choice.name_filter {
                Some(f) => format!("no adapter whose name contains {f:?}"),
                None => "no Vulkan adapter found (install mesa-vulkan-drivers for lavapipe)".into(),
            })
        })?;
        let info = adapter.get_info();
        let limits = adapter.limits();
        let needed = (WG as usize * NE * 4) as u32;
        if limits.max_compute_workgroup_storage_size < needed {
            return Err(EvalError::NoAdapter(format!(
                "{}: workgroup storage {} < {needed}",
                info.name, limits.max_compute_workgroup_storage_size
            )));
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("supertoroid"),
            required_features: wgpu::Features::empty(),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| EvalError::Device(e.to_string()))?;
        let failure = Arc::new(Mutex::new(None));
        let sink = failure.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            *sink.lock().unwrap() = Some(e.to_string());
        }));
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("meridian.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER_SOURCE.into()),
        });
        let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("meridian"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                storage(1, true),
                storage(2, true),
                storage(3, false),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("meridian"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let ctx = Self {
            residuals: pipeline("residuals"),
            normal_equations: pipeline("normal_equations"),
            costs: pipeline("costs"),
            device,
            queue,
            info,
            limits,
            layout,
            failure,
        };
        ctx.check()?;
        Ok(ctx)
    }

    /// "name (backend, device type)"
    pub fn adapter_name(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }

    /// Maps `slice` for reading once `submission` has finished (waits up to 60 s).
    pub fn map_for_reading(
        &self,
        slice: &wgpu::BufferSlice,
        submission: wgpu::SubmissionIndex,
    ) -> Result<(), EvalError> {
        let device = |e: &dyn std::fmt::Display| EvalError::Device(e.to_string());
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(submission),
                timeout: Some(std::time::Duration::from_secs(60)),
            })
            .map_err(|e| device(&e))?;
        rx.recv().map_err(|e| device(&e))?.map_err(|e| device(&e))
    }

    /// One dispatch of `pipeline` over `groups` workgroups with `bind_group`: the first
    /// `bytes` of `output` cleared before it and copied to `staging` after; submitted,
    /// waited for and returned as f32.
    pub(super) fn dispatch_and_read(
        &self,
        pipeline: &wgpu::ComputePipeline,
        bind_group: &wgpu::BindGroup,
        groups: (u32, u32),
        output: &wgpu::Buffer,
        staging: &wgpu::Buffer,
        bytes: u64,
    ) -> Result<Vec<f32>, EvalError> {
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("evaluate"),
            });
        encoder.clear_buffer(output, 0, Some(bytes));
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("evaluate"),
                timestamp_writes: None,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind_group, &[]);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        encoder.copy_buffer_to_buffer(output, 0, staging, 0, bytes);
        let submission = self.queue.submit(Some(encoder.finish()));
        let slice = staging.slice(..bytes);
        self.map_for_reading(&slice, submission)?;
        let values = {
            let view = slice
                .get_mapped_range()
                .map_err(|e| EvalError::Device(e.to_string()))?;
            bytemuck::cast_slice::<u8, f32>(&view).to_vec()
        };
        staging.unmap();
        self.check()?;
        Ok(values)
    }

    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    pub(super) fn check(&self) -> Result<(), EvalError> {
        match self.failure.lock().unwrap().clone() {
            Some(e) => Err(EvalError::Device(e)),
            None => Ok(()),
        }
    }
}

/// A buffer that grows (to the next power of two) and is never shrunk.
pub(super) struct Grown {
    pub(super) buffer: wgpu::Buffer,
    capacity: u64,
}

pub(super) fn ensure_buffer(
    ctx: &GpuContext,
    slot: &mut Option<Grown>,
    bytes: u64,
    usage: wgpu::BufferUsages,
    label: &str,
) -> bool {
    let bytes = bytes.max(16);
    if slot.as_ref().is_some_and(|g| g.capacity >= bytes) {
        return false;
    }
    let capacity = bytes.next_power_of_two();
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: capacity,
        usage,
        mapped_at_creation: false,
    });
    *slot = Some(Grown { buffer, capacity });
    true
}

/// The WGSL evaluator. Holds its own buffers; shares the process's [`GpuContext`].
pub struct GpuEvaluator {
    ctx: Arc<GpuContext>,
    /// (first, count, surface count) of each uploaded point set in the points buffer:
    /// its surface points, then its free-space points (w = 2)
    sets: Vec<(u32, u32, u32)>,
    params: wgpu::Buffer,
    points: Option<Grown>,
    candidates: Option<Grown>,
    output: Option<Grown>,
    staging: Option<Grown>,
    bind_group: Option<wgpu::BindGroup>,
    /// Reused upload scratch (no allocation per iteration).
    scratch: Vec<GpuCandidate>,
}

impl GpuEvaluator {
    pub fn new(ctx: Arc<GpuContext>) -> Self {
        let params = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: std::mem::size_of::<Params>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self {
            ctx,
            sets: Vec::new(),
            params,
            points: None,
            candidates: None,
            output: None,
            staging: None,
            bind_group: None,
            scratch: Vec::new(),
        }
    }

    pub fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    /// Workgroups along x per candidate, for candidates of at most `n_points` points:
    /// enough to fill the device, few enough that the partial sums read back stay small
    /// (at most ~1.5 MB for a whole batch).
    fn groups_x(n_points: usize, n_candidates: usize, software: bool) -> u32 {
        let target_total: usize = if software { 16 } else { 4096 };
        let needed = n_points.div_ceil(WG as usize).max(1);
        let short_enough = n_points.div_ceil(WG as usize * MAX_POINTS_PER_INVOCATION);
        (target_total / n_candidates.max(1))
            .max(short_enough)
            .clamp(1, needed) as u32
    }

    /// Uploads the candidates with their sets' ranges; returns the largest range.
    fn upload_candidates(
        &mut self,
        candidates: &[Candidate],
        sets: &[usize],
    ) -> Result<usize, EvalError> {
        // a set needs surface points: free space alone fits nothing
        let surface: Vec<usize> = self.sets.iter().map(|s| s.2 as usize).collect();
        check_sets(candidates.len(), sets, &surface)?;
        let sizes: Vec<usize> = self.sets.iter().map(|s| s.1 as usize).collect();
        let max_y = self.ctx.limits.max_compute_workgroups_per_dimension as usize;
        if candidates.is_empty() || candidates.len() > max_y {
            return Err(EvalError::TooLarge(format!(
                "{} candidates (1..={max_y} per dispatch)",
                candidates.len()
            )));
        }
        self.scratch.clear();
        self.scratch.extend(
            candidates
                .iter()
                .zip(sets)
                .map(|(c, &s)| GpuCandidate::from(c, (self.sets[s].0, self.sets[s].1))),
        );
        let bytes = std::mem::size_of_val(self.scratch.as_slice()) as u64;
        if ensure_buffer(
            &self.ctx,
            &mut self.candidates,
            bytes,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            "candidates",
        ) {
            self.bind_group = None;
        }
        self.ctx.queue.write_buffer(
            &self.candidates.as_ref().unwrap().buffer,
            0,
            bytemuck::cast_slice(&self.scratch),
        );
        Ok(sets.iter().map(|&s| sizes[s]).max().unwrap_or(0))
    }

    fn prepare_output(&mut self, bytes: u64) -> Result<(), EvalError> {
        if bytes > self.ctx.limits.max_storage_buffer_binding_size as u64 {
            return Err(EvalError::TooLarge(format!("{bytes} bytes of output")));
        }
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        if ensure_buffer(&self.ctx, &mut self.output, bytes, usage, "output") {
            self.bind_group = None;
        }
        ensure_buffer(
            &self.ctx,
            &mut self.staging,
            bytes,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            "staging",
        );
        Ok(())
    }

    fn bind_group(&mut self) -> wgpu::BindGroup {
        fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            }
        }
        if self.bind_group.is_none() {
            self.bind_group = Some(
                self.ctx
                    .device
                    .create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("meridian"),
                        layout: &self.ctx.layout,
                        entries: &[
                            entry(0, &self.params),
                            entry(1, &self.points.as_ref().unwrap().buffer),
                            entry(2, &self.candidates.as_ref().unwrap().buffer),
                            entry(3, &self.output.as_ref().unwrap().buffer),
                        ],
                    }),
            );
        }
        self.bind_group.clone().unwrap()
    }

    /// Records one dispatch and the copy of its output, submits, waits, and returns the
    /// output as f32.
    fn run(
        &mut self,
        pipeline: Pipeline,
        params: Params,
        groups: (u32, u32),
        out_values: usize,
    ) -> Result<Vec<f32>, EvalError> {
        self.ctx.check()?;
        let bytes = (out_values * 4) as u64;
        self.ctx
            .queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let bind_group = self.bind_group();
        let pipeline = match pipeline {
            Pipeline::Residuals => &self.ctx.residuals,
            Pipeline::NormalEquations => &self.ctx.normal_equations,
            Pipeline::Costs => &self.ctx.costs,
        };
        let output = &self.output.as_ref().unwrap().buffer;
        let staging = &self.staging.as_ref().unwrap().buffer;
        self.ctx
            .dispatch_and_read(pipeline, &bind_group, groups, output, staging, bytes)
    }

    /// Runs a reduction kernel whose workgroups each write `stride` values (the last one
    /// the completion marker) and finishes the partial sums per candidate in f64.
    fn reduce(
        &mut self,
        pipeline: Pipeline,
        stride: usize,
        candidates: &[Candidate],
        sets: &[usize],
        loss: Loss,
    ) -> Result<Vec<Vec<f64>>, EvalError> {
        let longest = self.upload_candidates(candidates, sets)?;
        let k = candidates.len();
        let groups_x = Self::groups_x(longest, k, self.ctx.is_software());
        let values = k * groups_x as usize * stride;
        self.prepare_output((values * 4) as u64)?;
        let (code, scale) = loss.code();
        let params = Params {
            n_points: longest as u32,
            n_candidates: k as u32,
            loss: code,
            groups_x,
            loss_scale: scale,
            _pad: [0.0; 3],
        };
        let out = self.run(pipeline, params, (groups_x, k as u32), values)?;
        check_markers(&out, stride)?;
        Ok(out
            .chunks(groups_x as usize * stride)
            .map(|partials| {
                let mut sum = vec![0.0f64; stride - 1];
                for part in partials.chunks(stride) {
                    for (s, v) in sum.iter_mut().zip(part) {
                        *s += *v as f64;
                    }
                }
                sum
            })
            .collect())
    }
}

/// Every partial ends in the marker 1.0 that its workgroup writes last.
pub(super) fn check_markers(out: &[f32], stride: usize) -> Result<(), EvalError> {
    if out.chunks(stride).all(|p| p[stride - 1] == 1.0) {
        Ok(())
    } else {
        Err(EvalError::Device(
            "the device did not complete the dispatch (missing completion markers)".into(),
        ))
    }
}

#[derive(Clone, Copy)]
enum Pipeline {
    Residuals,
    NormalEquations,
    Costs,
}

impl Evaluator for GpuEvaluator {
    fn kind(&self) -> &'static str {
        "gpu"
    }

    fn device_name(&self) -> String {
        self.ctx.adapter_name()
    }

    fn objective_device(&self) -> Option<Arc<super::GpuObjective>> {
        super::GpuObjective::shared(&self.ctx).ok()
    }

    fn set_point_sets_with_free_space(&mut self, sets: &[PointSet]) -> Result<(), EvalError> {
        let total: usize = sets
            .iter()
            .map(|s| s.surface.len() + s.free_space.len())
            .sum();
        let bytes = (total * 16) as u64;
        if bytes > self.ctx.limits.max_storage_buffer_binding_size as u64
            || total > u32::MAX as usize / 2
        {
            return Err(EvalError::TooLarge(format!("{total} points")));
        }
        // w: 1 a surface point, 2 a free-space point (0 is padding)
        let data: Vec<[f32; 4]> = sets
            .iter()
            .flat_map(|set| {
                let surface = set.surface.iter().map(|p| (p, 1.0));
                surface.chain(set.free_space.iter().map(|p| (p, 2.0)))
            })
            .map(|(p, w)| [p.x as f32, p.y as f32, p.z as f32, w])
            .collect();
        if ensure_buffer(
            &self.ctx,
            &mut self.points,
            bytes,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            "points",
        ) {
            self.bind_group = None;
        }
        if !data.is_empty() {
            self.ctx.queue.write_buffer(
                &self.points.as_ref().unwrap().buffer,
                0,
                bytemuck::cast_slice(&data),
            );
        }
        self.sets.clear();
        let mut first = 0u32;
        for set in sets {
            let count = (set.surface.len() + set.free_space.len()) as u32;
            self.sets.push((first, count, set.surface.len() as u32));
            first += count;
        }
        Ok(())
    }

    fn normal_equations_on(
        &mut self,
        candidates: &[Candidate],
        sets: &[usize],
        loss: Loss,
    ) -> Result<Vec<NormalEquations>, EvalError> {
        let sums = self.reduce(Pipeline::NormalEquations, NE_OUT, candidates, sets, loss)?;
        Ok(sums
            .iter()
            .map(|s| NormalEquations::from_packed(s))
            .collect())
    }

    fn costs_on(
        &mut self,
        candidates: &[Candidate],
        sets: &[usize],
        loss: Loss,
    ) -> Result<Vec<Cost>, EvalError> {
        let sums = self.reduce(Pipeline::Costs, COST_OUT, candidates, sets, loss)?;
        Ok(sums
            .iter()
            .map(|s| Cost {
                cost: s[0],
                count: s[1].round() as u64,
            })
            .collect())
    }

    fn residuals_on(
        &mut self,
        candidates: &[Candidate],
        sets: &[usize],
    ) -> Result<Vec<f64>, EvalError> {
        let longest = self.upload_candidates(candidates, sets)?;
        let k = candidates.len();
        let values = k * longest;
        self.prepare_output((values * 4) as u64)?;
        let params = Params {
            n_points: longest as u32,
            n_candidates: k as u32,
            loss: 0,
            groups_x: 0,
            loss_scale: 1.0,
            _pad: [0.0; 3],
        };
        let groups = ((longest as u32).div_ceil(WG_RESIDUALS), k as u32);
        if groups.0 > self.ctx.limits.max_compute_workgroups_per_dimension {
            return Err(EvalError::TooLarge(format!(
                "{longest} points for one residual dispatch"
            )));
        }
        // blocks of `longest` values per candidate, of which its set's count are written;
        // the surface points come first and are the ones returned
        let out = self.run(Pipeline::Residuals, params, groups, values)?;
        Ok(out
            .chunks(longest.max(1))
            .zip(sets)
            .flat_map(|(block, &s)| {
                block[..self.sets[s].2 as usize]
                    .iter()
                    .map(|&v| f64::from(v))
            })
            .collect())
    }
}
