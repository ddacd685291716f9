//! robcal's host tests in one binary: each file of this directory is a
//! module (`cargo test -p host-tests --test host -- <module>::` runs one),
//! so the generic code is compiled and linked once, and the tests of every
//! file share the cores as they run.

mod model_common;
mod paper_common;
mod tiago_common;
mod ur_like_common;

// The firmware's own sources (examples/), compiled on the host.
#[allow(dead_code)]
#[path = "../../examples/firmware_diagnose/closed_loop.rs"]
mod closed_loop;
#[allow(dead_code)]
#[path = "../../examples/firmware/kr270.rs"]
mod kr270;
#[path = "../../examples/firmware_plan/sequence.rs"]
mod plan_sequence;
#[allow(dead_code)]
#[path = "../../examples/firmware_diagnose/table.rs"]
mod table;

mod accumulator_errors;
mod accumulator_props;
mod calibrated_urdf;
mod compensate;
mod contacts;
mod coverage_base;
mod coverage_kr270;
mod coverage_mixed;
mod design_not_held;
mod device_diagnosis;
mod diagnose;
mod distributions;
mod effect_rule;
mod firmware_kr270;
mod fuzz_io_regressions;
mod fuzz_props;
mod fuzz_regressions;
mod gauss_newton;
mod grouped;
mod grouped_fit;
mod heldout_held_weights;
mod identifiability;
mod io_measurements;
mod io_setup;
mod io_urdf;
mod loop_effects;
mod loop_gravity;
mod loop_link_mass;
mod loop_own_weight;
mod loop_thermal;
mod model_columns;
mod model_equilibrium;
mod model_kinematics;
mod model_layout;
mod model_urdf;
mod paper_batch;
mod paper_estimates;
mod plan;
mod poses;
mod reported_error;
mod solve_covariance;
mod solve_errors;
mod tiago_calibration;
mod tiago_import;
mod tree_kinematics;
mod update_kernel;
mod wide_accumulator;
