// Method `chun-oh` (Chun & Oh 2016 §3): the PCSS filter (`filter.wgsl`, whose passes these
// are), then the adaptive quadtree over its tests (`quadtree.wgsl`): sub-region visibility ×
// the colour of the matching part of the light image, for coloured penumbrae.

#import methods/filter.wgsl
#import methods/chun_oh/quadtree.wgsl

fn light_region(i: u32) -> vec4<f32> {
    return light_regions[i];
}

// No blocker found: fully lit, nothing to split.
fn unblocked_visibility() -> vec3<f32> {
    return coloured_visibility(Subdivision(light_region(WHOLE).rgb, 0u, 0u), 1.0);
}

fn filtered_visibility(f: Filter) -> vec3<f32> {
    if !f.found_blocker {
        tally_add(0u, 1u);
        return unblocked_visibility();
    }
    let e0 = f32(f.lit) / f32(f.taps);
    let s = subdivide(e0, QuadtreeParams(params.mode, params.threshold, params.light_threshold, params.lattice / 4u));
    tally_add(4u, 1u);
    tally_add(3u, s.forced);
    tally_add(s.level, 1u);
    return coloured_visibility(s, e0);
}
