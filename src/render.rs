//! Pictures of a cloud with its fitted surface, rendered headless with the project's own
//! wgpu context (works on lavapipe): three orthographic views side by side — along the
//! hole axis, from the side, and oblique — into a PNG. A scene is drawn the same way
//! about its table's normal, each object's points and surface in a colour of its own.
//!
//! The host does the shading (Lambert on the mesh's normals, points coloured by their
//! distance to the fit), so the shader (`shaders/render.wgsl`) only transforms.

use crate::eval::{AdapterChoice, GpuContext};
use crate::io::mesh::tessellate;
use crate::io::ply::colormap;
use crate::model::{Pose, Shape, meridian_distance};
use glam::{DMat3, DVec3, Mat4, Vec3};
use std::sync::Arc;

const SHADER: &str = include_str!("../shaders/render.wgsl");
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Vertex {
    position: [f32; 3],
    color: [f32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ViewUniform {
    view_proj: [[f32; 4]; 4],
    point: [f32; 4],
}

/// What to draw.
pub struct Scene<'a> {
    pub points: &'a [DVec3],
    pub fit: Option<(Shape, Pose)>,
    /// a whole scene instead: every object's fitted surface, the points coloured by the
    /// object they belong to (`owners[i]`, an index into `objects`), the views about the
    /// table's normal `up` (from above, from the side, oblique)
    pub objects: Option<SceneObjects<'a>>,
}

pub struct SceneObjects<'a> {
    pub fits: &'a [(Shape, Pose)],
    pub owners: &'a [usize],
    pub up: DVec3,
}

/// Distinct colours for the objects of a scene, in turn.
const OBJECT_COLOURS: [[f32; 3]; 8] = [
    [0.90, 0.30, 0.25],
    [0.25, 0.60, 0.90],
    [0.35, 0.75, 0.35],
    [0.95, 0.70, 0.20],
    [0.65, 0.40, 0.85],
    [0.20, 0.80, 0.80],
    [0.90, 0.45, 0.70],
    [0.60, 0.60, 0.60],
];

/// Renders three `view_size`-pixel square views side by side and returns the PNG bytes
/// (width 3·view_size, height view_size).
pub fn render_png(scene: &Scene, view_size: u32) -> Result<Vec<u8>, String> {
    if !(16..=4096).contains(&view_size) {
        return Err("view size must be in 16..=4096 pixels".into());
    }
    if scene.points.is_empty() && scene.fit.is_none() && scene.objects.is_none() {
        return Err("nothing to draw".into());
    }
    let ctx = GpuContext::shared(&AdapterChoice::from_env()).map_err(|e| e.to_string())?;
    let rgba = render_rgba(&ctx, scene, view_size)?;
    let (width, height) = (3 * view_size, view_size);
    let rgb: Vec<u8> = rgba
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
        writer.write_image_data(&rgb).map_err(|e| e.to_string())?;
    }
    Ok(out)
}

/// The object's frame for the views: the fit's (hole axis up) or the world's.
fn view_frame(scene: &Scene) -> (DMat3, DVec3, f64) {
    let mut lo = DVec3::INFINITY;
    let mut hi = DVec3::NEG_INFINITY;
    for p in scene.points {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let (frame, centre) = match (&scene.fit, &scene.objects) {
        (_, Some(objects)) => {
            for (shape, pose) in objects.fits {
                let e = shape.half_extents().max_element();
                lo = lo.min(pose.translation - DVec3::splat(e));
                hi = hi.max(pose.translation + DVec3::splat(e));
            }
            let z = objects.up.normalize();
            let (x, y) = z.any_orthonormal_pair();
            (DMat3::from_cols(x, y, z), 0.5 * (lo + hi))
        }
        (Some((shape, pose)), None) => {
            let e = shape.half_extents();
            for corner in [-1.0, 1.0] {
                lo = lo.min(pose.translation + DVec3::splat(corner * e.max_element()));
                hi = hi.max(pose.translation + DVec3::splat(corner * e.max_element()));
            }
            (pose.matrix(), pose.translation)
        }
        (None, None) => (DMat3::IDENTITY, 0.5 * (lo + hi)),
    };
    let radius = scene
        .points
        .iter()
        .map(|p| (*p - centre).length())
        .fold(0.5 * (hi - lo).length(), f64::max)
        .max(1e-9);
    (frame, centre, radius)
}

fn render_rgba(ctx: &Arc<GpuContext>, scene: &Scene, size: u32) -> Result<Vec<u8>, String> {
    let device = &ctx.device;
    let (frame, centre, radius) = view_frame(scene);
    // everything relative to the centre, in f32
    let local = |p: DVec3| (p - centre).as_vec3().to_array();

    let light = (frame * DVec3::new(0.4, -0.5, 0.8)).normalize();
    let mut mesh_vertices: Vec<Vertex> = Vec::new();
    let mut mesh_indices: Vec<u32> = Vec::new();
    let mut point_colors = vec![[1.0f32, 0.55, 0.1]; scene.points.len()];
    let mut add_mesh = |shape: &Shape, pose: &Pose, tint: [f32; 3]| {
        let mesh = tessellate(shape, pose, 64, 128);
        let first = mesh_vertices.len() as u32;
        mesh_vertices.extend(mesh.vertices.iter().zip(&mesh.normals).map(|(v, n)| {
            let shade = (0.35 + 0.65 * n.dot(light).abs()) as f32;
            Vertex {
                position: local(*v),
                color: tint.map(|c| c * shade),
            }
        }));
        mesh_indices.extend(mesh.triangles.iter().flatten().map(|i| first + i));
    };
    if let Some(objects) = &scene.objects {
        for (k, (shape, pose)) in objects.fits.iter().enumerate() {
            // the surface a paler shade of its points' colour
            let tint = OBJECT_COLOURS[k % OBJECT_COLOURS.len()].map(|c| 0.5 + 0.4 * c);
            add_mesh(shape, pose, tint);
        }
        for (c, &owner) in point_colors.iter_mut().zip(objects.owners) {
            *c = OBJECT_COLOURS[owner % OBJECT_COLOURS.len()];
        }
    } else if let Some((shape, pose)) = &scene.fit {
        add_mesh(shape, pose, [0.55, 0.65, 0.8]);
        let scale = 0.05 * shape.size();
        for (c, p) in point_colors.iter_mut().zip(scene.points) {
            let d = meridian_distance(shape, pose.to_canonical(*p)).distance;
            *c = colormap((d / scale).min(1.0)).map(|v| v as f32 / 255.0);
        }
    }
    let points: Vec<Vertex> = scene
        .points
        .iter()
        .zip(&point_colors)
        .map(|(p, c)| Vertex {
            position: local(*p),
            color: *c,
        })
        .collect();

    use wgpu::util::DeviceExt;
    let buffer = |label, contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage,
        })
    };
    // a buffer may not be empty: pad with one vertex that is never drawn
    let pad = |v: &[Vertex]| {
        if v.is_empty() {
            vec![Vertex {
                position: [0.0; 3],
                color: [0.0; 3],
            }]
        } else {
            v.to_vec()
        }
    };
    let mesh_buffer = buffer(
        "mesh",
        bytemuck::cast_slice(&pad(&mesh_vertices)),
        wgpu::BufferUsages::VERTEX,
    );
    let index_buffer = buffer(
        "indices",
        bytemuck::cast_slice(if mesh_indices.is_empty() {
            &[0u32, 0, 0]
        } else {
            &mesh_indices[..]
        }),
        wgpu::BufferUsages::INDEX,
    );
    let point_buffer = buffer(
        "points",
        bytemuck::cast_slice(&pad(&points)),
        wgpu::BufferUsages::VERTEX,
    );

    // three views: along the hole axis, from the side, oblique (object frame)
    let directions = [DVec3::Z, -DVec3::Y, DVec3::new(1.0, -1.0, 0.8)];
    let ups = [DVec3::Y, DVec3::Z, DVec3::Z];
    let half_point = 2.5 / size as f32; // 2.5 pixels in NDC (2 units across)
    let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
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
    });
    let bind_groups: Vec<wgpu::BindGroup> = directions
        .iter()
        .zip(ups)
        .map(|(d, up)| {
            let eye = (frame * d.normalize() * (3.0 * radius)).as_vec3();
            let view = Mat4::look_at_rh(eye, Vec3::ZERO, (frame * up).as_vec3());
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
                "view",
                bytemuck::bytes_of(&uniform),
                wgpu::BufferUsages::UNIFORM,
            );
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("view"),
                layout: &bind_layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: ub.as_entire_binding(),
                }],
            })
        })
        .collect();

    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("render.wgsl"),
        source: wgpu::ShaderSource::Wgsl(SHADER.into()),
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("render"),
        bind_group_layouts: &[Some(&bind_layout)],
        immediate_size: 0,
    });
    let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];
    let pipeline = |entry: &str, step: wgpu::VertexStepMode, cull: Option<wgpu::Face>| {
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
                cull_mode: cull,
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
    let mesh_pipeline = pipeline("vs_mesh", wgpu::VertexStepMode::Vertex, None);
    let point_pipeline = pipeline("vs_points", wgpu::VertexStepMode::Instance, None);

    let (width, height) = (3 * size, size);
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
    let color_view = color.create_view(&Default::default());
    let depth_view = depth.create_view(&Default::default());
    let row_bytes = (width * 4).div_ceil(256) * 256;
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: (row_bytes * height) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });

    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("views"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &color_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::WHITE),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth_view,
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
        for (i, group) in bind_groups.iter().enumerate() {
            pass.set_viewport(
                (i as u32 * size) as f32,
                0.0,
                size as f32,
                size as f32,
                0.0,
                1.0,
            );
            pass.set_bind_group(0, group, &[]);
            if !mesh_indices.is_empty() {
                pass.set_pipeline(&mesh_pipeline);
                pass.set_vertex_buffer(0, mesh_buffer.slice(..));
                pass.set_index_buffer(index_buffer.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..mesh_indices.len() as u32, 0, 0..1);
            }
            if !points.is_empty() {
                pass.set_pipeline(&point_pipeline);
                pass.set_vertex_buffer(0, point_buffer.slice(..));
                pass.draw(0..6, 0..points.len() as u32);
            }
        }
    }
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture: &color,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &readback,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row_bytes),
                rows_per_image: Some(height),
            },
        },
        wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
    );
    let submission = ctx.queue.submit(Some(encoder.finish()));
    let slice = readback.slice(..);
    ctx.map_for_reading(&slice, submission)
        .map_err(|e| e.to_string())?;
    let mut rgba = Vec::with_capacity((width * height * 4) as usize);
    {
        let view = slice.get_mapped_range().map_err(|e| e.to_string())?;
        for row in 0..height {
            let start = (row * row_bytes) as usize;
            rgba.extend_from_slice(&view[start..start + (width * 4) as usize]);
        }
    }
    readback.unmap();
    Ok(rgba)
}
