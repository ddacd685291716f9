//! Writes `data/kr270/poses-6d.csv`: the KR-270 of `data/kr270` measured as
//! 6-D poses by a laser tracker's 6-D probe (20 µm and 30 µrad per axis),
//! 40 random poses within its limits, its joint zeros off by up to 1 mrad
//! and its tool frame by up to 0.5 mm and 0.5 mrad
//! (`host_tests::poses`, which shares no code with robcal's engine), for
//! `data/kr270/setup-6d.toml` and the README's pose command.
//!
//! ```sh
//! cargo run --release -p host-tests --example generate_kr270_poses
//! ```

use host_tests::poses::{csv, Arm, Instrument, Truth};
use robcal_paper::rng::SplitMix64;

fn main() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/kr270");
    let arm = Arm::kr270(&dir);
    let mut rng = SplitMix64::new(0x6b72_3237_3036);
    let truth = Truth::draw(&mut rng, arm.joints.len());
    let instrument = Instrument {
        sigma_m: 20e-6,
        sigma_rad: 30e-6,
    };
    let text = csv(&arm, &truth, instrument, 40, true, &mut rng);
    let path = dir.join("poses-6d.csv");
    std::fs::write(&path, text).expect("write");
    println!("wrote {}", path.display());
    println!(
        "truth: joint zeros {:?} mrad, tool translation {:?} mm, rotation {:?} mrad",
        truth.offsets.iter().map(|o| o * 1e3).collect::<Vec<_>>(),
        (truth.tool_t * 1e3).as_slice(),
        (truth.tool_r * 1e3).as_slice()
    );
}
