// Headless pictures of a cloud and its fitted surface (`supertoroid render`): a shaded
// triangle mesh and the points as small screen-space squares, colours computed on the host.

struct View {
    view_proj: mat4x4<f32>,
    // x: depth pulled towards the camera for points (NDC), y, z: half a point's size (NDC)
    point: vec4<f32>,
}

@group(0) @binding(0) var<uniform> view: View;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) color: vec3<f32>,
}

@vertex
fn vs_mesh(@location(0) position: vec3<f32>, @location(1) color: vec3<f32>) -> VsOut {
    var out: VsOut;
    out.clip = view.view_proj * vec4<f32>(position, 1.0);
    out.color = color;
    return out;
}

// One instance per point, six vertices per instance (two triangles of a square).
@vertex
fn vs_points(
    @builtin(vertex_index) corner: u32,
    @location(0) position: vec3<f32>,
    @location(1) color: vec3<f32>,
) -> VsOut {
    var offsets = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    var out: VsOut;
    let clip = view.view_proj * vec4<f32>(position, 1.0);
    let offset = offsets[corner % 6u] * view.point.yz * clip.w;
    let z = max(clip.z - view.point.x * clip.w, 0.0);
    out.clip = vec4<f32>(clip.xy + offset, z, clip.w);
    out.color = color;
    return out;
}

@fragment
fn fs(in: VsOut) -> @location(0) vec4<f32> {
    return vec4<f32>(in.color, 1.0);
}
