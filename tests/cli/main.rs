//! The `robcal` command, run as users run it: one test binary, a module
//! per command or concern (a single binary links the library once, and its
//! tests run side by side).

mod common;
mod round_trip;

mod apply;
mod calibrate;
mod hostile;
mod init;
mod input_errors;
mod plan;
mod real_data;
mod report;
mod threads;
mod tiago;
mod tree;
