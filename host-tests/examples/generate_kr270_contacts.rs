//! Writes `data/kr270/contacts.csv`: the KR-270 of `data/kr270` calibrated
//! without a tracker — 60 random poses within its limits, its probe
//! touching in turn the floor and two walls of a corner (a touch probe,
//! 10 µm), its joint zeros off by up to 1 mrad (the first's 0: it is the
//! base's turn about z) and its base 2.7 mm and 0.6 mrad off its nominal
//! place (`host_tests::contacts`, which shares no code with
//! robcal's engine), for `data/kr270/setup-contacts.toml` and the README's
//! command.
//!
//! ```sh
//! cargo run --release -p host-tests --example generate_kr270_contacts
//! ```

use host_tests::contacts::{csv, Target};
use host_tests::poses::{Arm, Truth};
use nalgebra::Vector3;
use robcal_paper::rng::SplitMix64;

fn main() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/kr270");
    let arm = Arm::kr270(&dir);
    let mut rng = SplitMix64::new(0x636f_726e_6572);
    let mut truth = Truth::draw(&mut rng, arm.joints.len());
    truth.offsets[0] = 0.0;
    truth.tool_t = Vector3::zeros();
    truth.tool_r = Vector3::zeros();
    // The planes as `setup-contacts.toml` declares them, in the world;
    // the robot's base stands off its nominal place there, `p_w = R p + t`:
    // in the robot's base frame a plane `n · p_w = d` is
    // `(Rᵀ n) · p = d − n · t`.
    let (r, t) = (
        nalgebra::Rotation3::new(Vector3::new(0.3e-3, -0.2e-3, 0.5e-3)),
        Vector3::new(2.0e-3, -1.5e-3, 0.8e-3),
    );
    let targets = [
        (1, Vector3::z(), 0.4),
        (2, Vector3::x(), 1.6),
        (3, Vector3::y(), 1.0),
    ]
    .map(|(id, n, d)| Target::Plane(id, r.transpose() * n, d - n.dot(&t)));
    let text = csv(&arm, &truth, &targets, 10e-6, 60, &mut rng);
    let path = dir.join("contacts.csv");
    std::fs::write(&path, text).expect("write");
    println!("wrote {}", path.display());
    println!(
        "truth: joint zeros {:?} mrad, the base at {:?} mm turned by {:?} mrad",
        truth.offsets.iter().map(|o| o * 1e3).collect::<Vec<_>>(),
        (t * 1e3).as_slice(),
        (r.scaled_axis() * 1e3).as_slice()
    );
}
