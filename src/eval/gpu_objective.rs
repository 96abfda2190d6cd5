//! The fit's objective on the GPU (`shaders/objective.wgsl`): the per-point sums of the
//! noise model's log-likelihood, its gradient and the BHHH outer product, for one
//! candidate's quadrature. `fit::objective` builds the quadrature and the constants at
//! the candidate ([`ObjectiveJob`]) and finishes the sums; its f64 loop over the same
//! quadrature is the reference the tests hold this one to.

use super::EvalError;
use super::gpu::{GpuContext, Grown, ensure_buffer};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// The kernel source, checked by naga in the tests and compiled by wgpu on first use.
pub const OBJECTIVE_SHADER_SOURCE: &str = include_str!("../../shaders/objective.wgsl");

/// Workgroup size (`WG` in the shader).
const WG: u32 = 32;
/// Values per workgroup partial: ln p, 13 partials, 91 products (`NV`), and the marker.
const NV: usize = 105;
const NV_OUT: usize = NV + 1;
/// Parameters of the objective (`fit::objective::PARAMETERS`).
pub const OBJECTIVE_PARAMETERS: usize = 13;
/// Points per invocation at most (lavapipe drops dispatches whose invocations run long).
const MAX_POINTS_PER_INVOCATION: usize = 8;

/// The constants of one evaluation, laid out as the shader's `Params`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ObjectiveParams {
    pub n_points: u32,
    pub n_nodes: u32,
    pub n_sweep: u32,
    pub groups_x: u32,
    /// 1: the gradient; 2: a sensor; 4: the cells' visibility is held
    pub flags: u32,
    /// the normaliser's sectors per ring
    pub sectors: u32,
    pub _pad: [u32; 2],
    /// the rotation's columns (canonical -> world), translation, viewpoint (w unused)
    pub columns: [[f32; 4]; 3],
    pub translation: [f32; 4],
    pub viewpoint: [f32; 4],
    /// a1 a2 a3 a4
    pub sizes: [f32; 4],
    /// sigma², the cutoff distance, the kernel's floor, the inliers' factor
    pub kernel: [f32; 4],
    /// the outliers' density (x)
    pub outlier: [f32; 4],
    /// d ln A / d (shape, translation, turn)
    pub d_log_area: [[f32; 4]; 3],
}

pub const FLAG_GRADIENT: u32 = 1;
pub const FLAG_SENSOR: u32 = 2;
pub const FLAG_VISIBILITY: u32 = 4;

/// One evaluation: the points (xyz and range weight), the quadrature at the candidate
/// (three vec4 per section node and per sweep sample, see the shader), the cells (rings
/// of the nodes, sectors of the samples, the visibility of each normaliser cell) and
/// the constants (`n_points`, `n_nodes`, `n_sweep` and `groups_x` are set here).
pub struct ObjectiveJob<'a> {
    pub points: &'a [[f32; 4]],
    pub nodes: &'a [[f32; 4]],
    pub sweep: &'a [[f32; 4]],
    pub cells: &'a [u32],
    pub params: ObjectiveParams,
}

/// The sums over the points: of ln p, of its gradient, and of the gradient's outer
/// product (full, symmetric).
#[derive(Clone, Debug)]
pub struct ObjectiveSums {
    pub log_likelihood: f64,
    pub gradient: [f64; OBJECTIVE_PARAMETERS],
    pub outer: [[f64; OBJECTIVE_PARAMETERS]; OBJECTIVE_PARAMETERS],
}

/// The objective's pipeline and buffers on the process's [`GpuContext`]. Evaluations
/// from many threads take turns on it.
pub struct GpuObjective {
    ctx: Arc<GpuContext>,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    buffers: Mutex<Buffers>,
    /// evaluations completed on the device
    evaluations: AtomicU64,
}

#[derive(Default)]
struct Buffers {
    params: Option<Grown>,
    points: Option<Grown>,
    nodes: Option<Grown>,
    sweep: Option<Grown>,
    cells: Option<Grown>,
    output: Option<Grown>,
    staging: Option<Grown>,
    bind_group: Option<wgpu::BindGroup>,
}

impl GpuObjective {
    /// Compiles the objective's kernel on `ctx`.
    pub fn new(ctx: Arc<GpuContext>) -> Result<Self, EvalError> {
        let device = &ctx.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("objective.wgsl"),
            source: wgpu::ShaderSource::Wgsl(OBJECTIVE_SHADER_SOURCE.into()),
        });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let read = wgpu::BufferBindingType::Storage { read_only: true };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("objective"),
            entries: &[
                entry(0, wgpu::BufferBindingType::Uniform),
                entry(1, read),
                entry(2, read),
                entry(3, read),
                entry(4, read),
                entry(5, wgpu::BufferBindingType::Storage { read_only: false }),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("objective"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("likelihood"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("likelihood"),
            compilation_options: Default::default(),
            cache: None,
        });
        ctx.check()?;
        Ok(Self {
            ctx,
            layout,
            pipeline,
            buffers: Mutex::new(Buffers::default()),
            evaluations: AtomicU64::new(0),
        })
    }

    /// The process's one objective on `ctx` (the process's one context,
    /// [`GpuContext::shared`]), compiled on first use; on another context a new one.
    pub fn shared(ctx: &Arc<GpuContext>) -> Result<Arc<GpuObjective>, EvalError> {
        static SHARED: std::sync::OnceLock<Result<Arc<GpuObjective>, String>> =
            std::sync::OnceLock::new();
        let shared = SHARED
            .get_or_init(|| {
                GpuObjective::new(ctx.clone())
                    .map(Arc::new)
                    .map_err(|e| e.to_string())
            })
            .clone()
            .map_err(EvalError::Device)?;
        if Arc::ptr_eq(&shared.ctx, ctx) {
            Ok(shared)
        } else {
            GpuObjective::new(ctx.clone()).map(Arc::new)
        }
    }

    /// The sums of one evaluation ([`ObjectiveJob`]).
    pub fn sums(&self, job: &ObjectiveJob) -> Result<ObjectiveSums, EvalError> {
        if job.points.is_empty() || job.nodes.is_empty() || job.sweep.is_empty() {
            return Err(EvalError::NoPoints);
        }
        let ctx = &self.ctx;
        ctx.check()?;
        let n = job.points.len();
        let needed = n.div_ceil(WG as usize);
        let groups_x = needed
            .div_ceil(MAX_POINTS_PER_INVOCATION)
            .max(needed.min(if ctx.is_software() { 16 } else { 4096 }))
            .clamp(1, ctx.limits.max_compute_workgroups_per_dimension as usize);
        let params = ObjectiveParams {
            n_points: n as u32,
            n_nodes: (job.nodes.len() / 3) as u32,
            n_sweep: (job.sweep.len() / 3) as u32,
            groups_x: groups_x as u32,
            ..job.params
        };
        let out_values = groups_x * NV_OUT;
        let out_bytes = (out_values * 4) as u64;
        let mut b = self.buffers.lock().unwrap_or_else(|e| e.into_inner());
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let uniform = wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST;
        // (a binding may not be empty)
        let cells: &[u32] = if job.cells.is_empty() {
            &[0]
        } else {
            job.cells
        };
        let Buffers {
            params: params_buffer,
            points,
            nodes,
            sweep,
            cells: cells_buffer,
            output,
            staging,
            bind_group,
        } = &mut *b;
        let mut grown = false;
        let mut upload = |slot: &mut Option<Grown>, bytes: &[u8], usage, label| {
            grown |= ensure_buffer(ctx, slot, bytes.len() as u64, usage, label);
            ctx.queue
                .write_buffer(&slot.as_ref().unwrap().buffer, 0, bytes);
        };
        upload(
            params_buffer,
            bytemuck::bytes_of(&params),
            uniform,
            "objective params",
        );
        upload(
            points,
            bytemuck::cast_slice(job.points),
            storage,
            "objective points",
        );
        upload(
            nodes,
            bytemuck::cast_slice(job.nodes),
            storage,
            "objective nodes",
        );
        upload(
            sweep,
            bytemuck::cast_slice(job.sweep),
            storage,
            "objective sweep",
        );
        upload(
            cells_buffer,
            bytemuck::cast_slice(cells),
            storage,
            "objective cells",
        );
        let read_back = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        grown |= ensure_buffer(ctx, output, out_bytes, read_back, "objective output");
        let mapped = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        ensure_buffer(ctx, staging, out_bytes, mapped, "objective staging");
        // (the bind group holds the buffers: made again only when one of them grew)
        if grown || bind_group.is_none() {
            let bound = [
                buffer(params_buffer),
                buffer(points),
                buffer(nodes),
                buffer(sweep),
                buffer(cells_buffer),
                buffer(output),
            ];
            let entries: Vec<wgpu::BindGroupEntry> = bound
                .iter()
                .enumerate()
                .map(|(i, buffer)| wgpu::BindGroupEntry {
                    binding: i as u32,
                    resource: buffer.as_entire_binding(),
                })
                .collect();
            *bind_group = Some(ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("objective"),
                layout: &self.layout,
                entries: &entries,
            }));
        }
        let values = ctx.dispatch_and_read(
            &self.pipeline,
            bind_group.as_ref().unwrap(),
            (groups_x as u32, 1),
            buffer(output),
            buffer(staging),
            out_bytes,
        )?;
        super::gpu::check_markers(&values, NV_OUT)?;
        self.evaluations.fetch_add(1, Ordering::Relaxed);
        Ok(finish(&values))
    }

    /// How many evaluations the device has completed (a fit on the GPU evaluator counts
    /// its search's likelihood here).
    pub fn evaluations(&self) -> u64 {
        self.evaluations.load(Ordering::Relaxed)
    }
}

/// The buffer a grown slot holds (every slot is filled before it is bound).
fn buffer(slot: &Option<Grown>) -> &wgpu::Buffer {
    &slot.as_ref().expect("filled before binding").buffer
}

/// The workgroups' partials added up in f64 and unpacked.
fn finish(values: &[f32]) -> ObjectiveSums {
    let mut total = [0.0f64; NV];
    for part in values.chunks(NV_OUT) {
        for (t, v) in total.iter_mut().zip(part) {
            *t += f64::from(*v);
        }
    }
    let mut sums = ObjectiveSums {
        log_likelihood: total[0],
        gradient: [0.0; OBJECTIVE_PARAMETERS],
        outer: [[0.0; OBJECTIVE_PARAMETERS]; OBJECTIVE_PARAMETERS],
    };
    sums.gradient
        .copy_from_slice(&total[1..1 + OBJECTIVE_PARAMETERS]);
    let mut idx = 1 + OBJECTIVE_PARAMETERS;
    for a in 0..OBJECTIVE_PARAMETERS {
        for b in a..OBJECTIVE_PARAMETERS {
            sums.outer[a][b] = total[idx];
            sums.outer[b][a] = total[idx];
            idx += 1;
        }
    }
    sums
}
