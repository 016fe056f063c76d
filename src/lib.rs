//! penumbra: a render-as-a-service daemon for soft shadows from coloured area lights.
//!
//! The data flow of one job: `job` (the contract) → `scene` and `light` (assets) → `gpu`
//! (device, pools, timing) → `render` (the frame, pass by pass) → `methods` (one module per
//! shadow method) → `output` (PNG/EXR). `engine` holds the warm state behind both the CLI and
//! `server`. See ARCHITECTURE.md for the map.

pub mod client;
pub mod color;
pub mod config;
pub mod daemon_bench;
pub mod engine;
pub mod error;
pub mod eval;
pub mod gpu;
pub mod image_input;
pub mod job;
pub mod light;
pub mod methods;
pub mod model;
pub mod output;
pub mod params;
pub mod quality;
pub mod queue;
pub mod render;
pub mod scene;
pub mod server;
pub mod store;
pub mod supervise;
pub mod timing;
pub mod upload_store;

#[cfg(test)]
mod tidy;
