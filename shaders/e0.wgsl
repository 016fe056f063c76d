// The unshadowed irradiance E0 (contract §1), identical for every method: Lambert's closed
// form over each uniform cell of the light image, times the cell's radiance, summed.

#import common/frame_inputs.wgsl

@group(1) @binding(0) var e0_out: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let pixel = id.xy;
    if any(pixel >= frame.sizes.xy) {
        return;
    }
    var e0 = vec3<f32>(0.0);
    if covered(pixel) {
        let x = textureLoad(gbuf_position, pixel, 0).xyz;
        let nx = textureLoad(gbuf_normal, pixel, 0).xyz;
        // One-sided emitter: only the lit side of the light plane receives light.
        if dot(x - frame.light_center.xyz, frame.light_n.xyz) > 0.0 {
            for (var k = 0u; k < frame.sizes.w; k++) {
                let cell = light_cells[k];
                e0 += cell.radiance.rgb * polygon_irradiance(x, nx, cell.corners);
            }
        }
    }
    textureStore(e0_out, pixel, vec4<f32>(e0, 1.0));
}
