//! `robcal init`: a commented setup file for a robot, with every key of the
//! data contract (section 2 and 7) and its default, the robot's movable
//! joints named where a key takes them, and the CSV header the measurements
//! need. The text parses as a [`crate::io::setup::Setup`] and passes
//! [`crate::io::setup::Setup::check_robot`] as written.

use std::fmt::Write as _;

use crate::io::urdf::Robot;

/// The setup text for `robot`, read from `robot_path` (written as given:
/// relative paths are relative to the setup file's directory).
pub fn setup_template(robot_path: &str, robot: &Robot) -> String {
    let joints = robot.joint_names.join(", ");
    let quoted: Vec<String> = robot
        .joint_names
        .iter()
        .map(|j| format!("\"{j}\""))
        .collect();
    let mut t = String::new();
    let _ = writeln!(
        t,
        "# robcal setup for '{}' ({} movable joints from '{}' to '{}': {joints}).",
        robot.name,
        robot.joint_names.len(),
        robot.base_link,
        robot.tip_link
    );
    let _ = writeln!(
        t,
        "# Every key with its default; uncomment and edit. Formats: docs/formats.md.\n\
         # The measurement CSV's header for this robot:\n\
         #   config,rep,marker,load_kg,{},x,y,z\n\
         # (rep, marker and load_kg may be left out with one marker and no [load];\n\
         #  extra columns go in ignore_columns below; an optional t column is time in s.)\n",
        robot.joint_names.join(",")
    );
    let _ = writeln!(t, "robot = {}", toml_string(robot_path));
    let _ = writeln!(t, "base_link = {}", toml_string(&robot.base_link));
    let _ = writeln!(
        t,
        "tip_link = {}    # markers and the load are given in this frame",
        toml_string(&robot.tip_link)
    );
    t.push_str(
        "# ignore_columns = []       # CSV columns to skip, e.g. [\"temperature\"]\n\
         # assumed_link_mass_kg = 2.0  # kg on every moving body without an <inertial> mass (default: none)\n\n\
         [units]                     # of the CSV's joint and position columns\n\
         angle = \"rad\"               # \"rad\" | \"deg\"\n\
         length = \"m\"                # \"m\" | \"mm\"\n\n\
         # One table per marker (tracker reflector, mocap point); ids as in the CSV.\n\
         [[marker]]\n\
         id = 1\n\
         xyz = [0.0, 0.0, 0.0]       # m, nominal, in tip_link\n\
         # link = \"...\"              # the link it is on (default: tip_link); other links make a tree\n\n\
         # [load]                    # the calibration load; omit when there is none\n\
         # com = [0.0, 0.0, 0.0]     # m, its centre of mass in tip_link\n\
         # gravity = [0.0, 0.0, -9.80665]   # m/s², in base_link\n\n\
         [noise]\n\
         sigma0_um = 10.0            # the instrument's noise floor (eq. 14), µm\n\
         # weights = \"both\"          # \"estimated\" | \"instrument\" | \"both\" (default: \"both\" with sx, sy, sz, else \"estimated\")\n\
         lambda = 1.0                # weight of the estimated σ (eq. 14), ≥ 0\n\n\
         [model]                     # what is identified\n",
    );
    let _ = writeln!(
        t,
        "compliance = []             # joint compliances, of: [{}]",
        quoted.join(", ")
    );
    t.push_str(
        "compliance_by_angle = []    # a compliance per angle of a joint (a gravity compensator)\n\
         geometry = \"none\"           # \"none\" | \"joint_offsets\" | \"full\" | \"select\"\n\
         base_frame = false          # identify the base's 6-D pose in the measurement frame\n\
         markers = \"nominal\"         # \"nominal\" | \"identify\"\n\
         tool_frame = false          # identify the tip link's 6-D pose error (moves every marker together)\n",
    );
    t
}

/// `s` as a TOML basic string.
fn toml_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{:04X}", u32::from(c));
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn strings_are_escaped() {
        assert_eq!(
            crate::io::template::toml_string("a\"b\\c\n"),
            "\"a\\\"b\\\\c\\u000A\""
        );
    }
}
