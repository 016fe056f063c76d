//! Fuzzes the job parser and validator: any bytes give a job or a 4xx-class error, never a
//! panic, and a valid job's merge with a built-in scene's defaults never panics either.
#![no_main]

use libfuzzer_sys::fuzz_target;
use penumbra::job::{Job, Limits};

fuzz_target!(init: penumbra_fuzz_init(), |data: &[u8]| {
    if let Ok(job) = Job::from_json(data) {
        let _ = penumbra::engine::check_job(&job, &Limits::default());
    }
});

/// A crash is a panic that escapes penumbra's API (libfuzzer-sys aborts on those). libFuzzer's
/// default hook would also abort on a panic penumbra catches on purpose (the glTF loader turns
/// a panic inside the `gltf` crate into `invalid_asset`), so the hook only stays quiet.
fn penumbra_fuzz_init() {
    std::panic::set_hook(Box::new(|_| {}));
}
