// Method `brabec`, pass 2: lists for the search (§3.3) the pixels adaptive sampling always
// searches — every 4th pixel of every 4th row, plus the last row and column — or, with
// `adaptive` off, every pixel (dispatched over the whole image).

#import methods/brabec/common.wgsl

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    frame = frame_uniform;
    params = params_uniform;
    let size = frame.sizes.xy;
    let last = size - vec2<u32>(1u);
    let pixel = min(id.xy * params.lattice_stride, last);
    // The lattice plus the last row and column (groups at the borders may be shorter).
    if any(id.xy * params.lattice_stride > last + vec2<u32>(params.lattice_stride - 1u)) {
        return;
    }
    mark(pixel);
}
