//! `probe_adapter` (what `--backend auto` decides from) names the adapter a `GpuVoxelizer`
//! opens, with the same software flag. Needs an adapter (lavapipe is enough): without one it
//! FAILS.

use voxlod_gpu::{probe_adapter, GpuMethod, GpuVoxelizer, DEFAULT_CUTOFF};
use voxlod_voxelize::Mode;

#[test]
fn probe_names_the_adapter_the_voxelizer_opens() {
    let probe = probe_adapter()
        .unwrap_or_else(|e| panic!("this test needs a GPU adapter (lavapipe is enough): {e}"));
    let gpu = GpuVoxelizer::new(Mode::Conservative, GpuMethod::Hybrid, DEFAULT_CUTOFF)
        .unwrap_or_else(|e| panic!("this test needs a GPU adapter (lavapipe is enough): {e}"));
    assert_eq!(probe.name, gpu.adapter_name());
    assert_eq!(probe.software, gpu.is_software());
    // lavapipe and llvmpipe say so in their names; a probe must call them software
    let lower = probe.name.to_lowercase();
    if lower.contains("llvmpipe") || lower.contains("lavapipe") {
        assert!(probe.software, "{} is a software adapter", probe.name);
    }
}
