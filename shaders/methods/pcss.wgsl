// Method `pcss` (Fernando 2005): blocker search, penumbra estimate from the light's size and
// the blocker/receiver depths, percentage-closer filtering — the plain average of the filter's
// shadow tests, gray. The baseline Chun & Oh 2016 improve on (their Table 1's "average
// visibility" method). The passes are `filter.wgsl`'s.

#import methods/filter.wgsl

// A pixel whose blocker search finds nothing: all of the filter's tests are lit.
fn unblocked_visibility() -> vec3<f32> {
    return vec3<f32>(1.0);
}

fn filtered_visibility(f: Filter) -> vec3<f32> {
    tally_add(0u, 1u);
    tally_add(4u, u32(f.found_blocker));
    return vec3<f32>(f32(f.lit) / f32(f.taps));
}
