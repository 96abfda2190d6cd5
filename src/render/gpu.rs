//! The views drawn on the GPU context: the geometry's buffers, one uniform per view, a
//! pipeline for the meshes and one for the points (instanced squares), one render pass
//! with a viewport per view, and the pixels read back.

use super::geometry::{Geometry, Vertex, ViewFrame};
use crate::eval::GpuContext;
use glam::{DVec3, Mat4, Vec3};
use wgpu::util::DeviceExt;

const SHADER: &str = include_str!("../../shaders/render.wgsl");
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ViewUniform {
    view_proj: [[f32; 4]; 4],
    /// depth offset of the points (towards the eye), half a point's width and height in
    /// clip units
    point: [f32; 4],
}

/// Three views of `geometry`, `size` pixels square, side by side: along the frame's z
/// (the hole axis), from the side, oblique. RGBA rows, 3·size wide, top row first.
pub(super) fn render_rgba(
    ctx: &GpuContext,
    geometry: &Geometry,
    frame: &ViewFrame,
    size: u32,
) -> Result<Vec<u8>, String> {
    let device = &ctx.device;
    let buffers = Buffers::new(device, geometry);
    let layout = view_layout(device);
    let views = view_bind_groups(device, &layout, frame, size);
    let pipelines = Pipelines::new(device, &layout);
    let target = Target::new(device, 3 * size, size);
    let mut encoder = device.create_command_encoder(&Default::default());
    draw(&mut encoder, &target, &buffers, &pipelines, &views, size);
    target.copy_out(&mut encoder);
    let submission = ctx.queue.submit(Some(encoder.finish()));
    target.read_back(ctx, submission)
}

/// The geometry on the device (a buffer may not be empty: an empty list is padded with
/// one vertex or triangle that is never drawn).
struct Buffers {
    mesh: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    points: wgpu::Buffer,
    point_count: u32,
}

impl Buffers {
    fn new(device: &wgpu::Device, geometry: &Geometry) -> Self {
        let indices: &[u32] = if geometry.indices.is_empty() {
            &[0, 0, 0]
        } else {
            &geometry.indices
        };
        Self {
            mesh: buffer(
                device,
                "mesh",
                bytemuck::cast_slice(or_unused(&geometry.mesh)),
                wgpu::BufferUsages::VERTEX,
            ),
            indices: buffer(
                device,
                "indices",
                bytemuck::cast_slice(indices),
                wgpu::BufferUsages::INDEX,
            ),
            index_count: geometry.indices.len() as u32,
            points: buffer(
                device,
                "points",
                bytemuck::cast_slice(or_unused(&geometry.points)),
                wgpu::BufferUsages::VERTEX,
            ),
            point_count: geometry.points.len() as u32,
        }
    }
}

/// One vertex that is never drawn, for an empty list (a buffer may not be empty).
const UNUSED: [Vertex; 1] = [Vertex {
    position: [0.0; 3],
    color: [0.0; 3],
}];

/// `vertices`, or [`UNUSED`] where there are none (the vertices themselves: no copy).
fn or_unused(vertices: &[Vertex]) -> &[Vertex] {
    if vertices.is_empty() {
        &UNUSED
    } else {
        vertices
    }
}

fn buffer(
    device: &wgpu::Device,
    label: &str,
    contents: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage,
    })
}

/// The bind group layout of a view: its uniform, read by the vertex stage.
fn view_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("view"),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::VERTEX,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        }],
    })
}

/// One bind group per view: an orthographic camera at three radii from the centre, along
/// the frame's z (y up), from the side (-y, z up) and oblique (z up), framing the radius.
fn view_bind_groups(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    frame: &ViewFrame,
    size: u32,
) -> Vec<wgpu::BindGroup> {
    let directions = [DVec3::Z, -DVec3::Y, DVec3::new(1.0, -1.0, 0.8)];
    let ups = [DVec3::Y, DVec3::Z, DVec3::Z];
    let radius = frame.radius;
    let half_point = 2.5 / size as f32; // 2.5 pixels in NDC (2 units across)
    directions
        .iter()
        .zip(ups)
        .map(|(d, up)| {
            let eye = (frame.axes * d.normalize() * (3.0 * radius)).as_vec3();
            let view = Mat4::look_at_rh(eye, Vec3::ZERO, (frame.axes * up).as_vec3());
            let r = (1.05 * radius) as f32;
            let proj = Mat4::orthographic_rh(-r, r, -r, r, 0.0, (6.0 * radius) as f32);
            let uniform = ViewUniform {
                view_proj: (proj * view).to_cols_array_2d(),
                point: [
                    (0.01 * radius / (6.0 * radius)) as f32,
                    half_point,
                    half_point,
                    0.0,
                ],
            };
            let ub = buffer(
                device,
                "view",
                bytemuck::bytes_of(&uniform),
                wgpu::BufferUsages::UNIFORM,
            );
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("view"),
                layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: ub.as_entire_binding(),
                }],
            })
        })
        .collect()
}

/// The meshes' pipeline (a vertex per corner) and the points' (a square per instance).
struct Pipelines {
    mesh: wgpu::RenderPipeline,
    points: wgpu::RenderPipeline,
}

impl Pipelines {
    fn new(device: &wgpu::Device, view_layout: &wgpu::BindGroupLayout) -> Self {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("render.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render"),
            bind_group_layouts: &[Some(view_layout)],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];
        let pipeline = |entry: &str, step: wgpu::VertexStepMode| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(entry),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    buffers: &[Some(wgpu::VertexBufferLayout {
                        array_stride: std::mem::size_of::<Vertex>() as u64,
                        step_mode: step,
                        attributes: &attributes,
                    })],
                },
                primitive: wgpu::PrimitiveState {
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::LessEqual),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs"),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: FORMAT,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        Self {
            mesh: pipeline("vs_mesh", wgpu::VertexStepMode::Vertex),
            points: pipeline("vs_points", wgpu::VertexStepMode::Instance),
        }
    }
}

/// The colour and depth textures drawn into, and the buffer their pixels come back in
/// (rows padded to 256 bytes, as a texture copy requires).
struct Target {
    width: u32,
    height: u32,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    row_bytes: u32,
    readback: wgpu::Buffer,
}

impl Target {
    fn new(device: &wgpu::Device, width: u32, height: u32) -> Self {
        let texture = |format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some("target"),
                size: wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let color = texture(
            FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let depth = texture(DEPTH, wgpu::TextureUsages::RENDER_ATTACHMENT);
        let row_bytes = (width * 4).div_ceil(256) * 256;
        Self {
            width,
            height,
            color_view: color.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            color,
            row_bytes,
            readback: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("readback"),
                size: (row_bytes * height) as u64,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
        }
    }

    /// The colour texture copied into the readback buffer.
    fn copy_out(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.color,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.row_bytes),
                    rows_per_image: Some(self.height),
                },
            },
            wgpu::Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
        );
    }

    /// The pixels, once `submission` is done, without the rows' padding.
    fn read_back(
        &self,
        ctx: &GpuContext,
        submission: wgpu::SubmissionIndex,
    ) -> Result<Vec<u8>, String> {
        let slice = self.readback.slice(..);
        ctx.map_for_reading(&slice, submission)
            .map_err(|e| e.to_string())?;
        let mut rgba = Vec::with_capacity((self.width * self.height * 4) as usize);
        {
            let view = slice.get_mapped_range().map_err(|e| e.to_string())?;
            for row in 0..self.height {
                let start = (row * self.row_bytes) as usize;
                rgba.extend_from_slice(&view[start..start + (self.width * 4) as usize]);
            }
        }
        self.readback.unmap();
        Ok(rgba)
    }
}

/// One render pass: cleared to white, then per view (its third of the target) the meshes
/// and the points.
fn draw(
    encoder: &mut wgpu::CommandEncoder,
    target: &Target,
    buffers: &Buffers,
    pipelines: &Pipelines,
    views: &[wgpu::BindGroup],
    size: u32,
) {
    let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("views"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: &target.color_view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::WHITE),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: &target.depth_view,
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(1.0),
                store: wgpu::StoreOp::Store,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    for (i, group) in views.iter().enumerate() {
        pass.set_viewport(
            (i as u32 * size) as f32,
            0.0,
            size as f32,
            size as f32,
            0.0,
            1.0,
        );
        pass.set_bind_group(0, group, &[]);
        if buffers.index_count > 0 {
            pass.set_pipeline(&pipelines.mesh);
            pass.set_vertex_buffer(0, buffers.mesh.slice(..));
            pass.set_index_buffer(buffers.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..buffers.index_count, 0, 0..1);
        }
        if buffers.point_count > 0 {
            pass.set_pipeline(&pipelines.points);
            pass.set_vertex_buffer(0, buffers.points.slice(..));
            pass.draw(0..6, 0..buffers.point_count);
        }
    }
}
