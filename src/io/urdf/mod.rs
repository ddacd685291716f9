//! URDF → [`Chain`]: the serial chain from `base_link` to `tip_link`, with
//! joint names, kinds and limits, and the mass properties of each moving body.
//! With markers on other links ([`Robot::load_tree`], data contract 7.1) the
//! chain holds every path from `base_link` to `tip_link` and to those links,
//! a joint shared by several paths once: a tree when a link is off the path
//! to the tip. [`Robot::ends`] says where each of those links is fixed.
//!
//! - Revolute, continuous and prismatic joints move. Fixed joints on the path
//!   are folded into the origin of the next movable joint
//!   (`origin_j = F_1 · F_2 ⋯ F_k · O_j`); the fixed joints after the last
//!   movable joint form the chain's `tip`.
//! - Link inertia of movable joint `j`: the mass and mass-weighted centre of
//!   mass (in joint `j`'s frame) of its child link and of every link fixed to
//!   it, side branches included, i.e. every link reached from the child
//!   through fixed joints only. This includes links fixed beyond `tip_link`
//!   (a tool flange, a gripper body): they load the last joint whatever frame
//!   the markers are given in.
//! - Movable joints that are not on the chain (a head on the torso, mimic
//!   gripper fingers, the joints after `tip_link` when the tip is mid-arm)
//!   carry bodies whose pose the measurements do not give: their subtrees are
//!   left out of every link inertia and listed in [`Robot::off_chain`] with
//!   their mass, so a caller can see what gravity load is missing. Links
//!   fixed to the base (before the first movable joint) are not part of any
//!   moving body and are ignored.
//! - A link without `<inertial>` has mass 0; a moving body of total mass 0
//!   gets `link: None` (unknown).
//!
//! Rejected (one [`InputError`] naming the URDF file, and the joint's line
//! where it can be found): XML that does not parse, a link that is the child
//! of two joints, a joint naming a link that does not exist, an unknown
//! `base_link`/`tip_link`, no path from base to tip, a planar, floating or
//! spherical joint on the path, a mimic joint on the path, a zero axis, more
//! than [`MAX_JOINTS`] movable joints, no movable joint at all, a non-finite
//! number (origin, axis, limit, mass, centre of mass), an origin beyond
//! [`crate::io::units::MAX_POSITION_M`] or a negative mass.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use crate::io::{error::ErrorKind, error::InputError};
use crate::robot::{Chain, End, JointKind};

/// Capacity of [`Robot::chain`]: the most movable joints a chain may have.
pub const MAX_JOINTS: usize = 24;

/// XML elements nested deeper than this are refused before the URDF parser
/// sees the text (it recurses once per level; a URDF needs 4 or 5).
pub const MAX_XML_DEPTH: usize = 64;

/// More XML elements than this are refused before the URDF parser sees the
/// text (its tree takes ~50 bytes of memory per byte of such a file; a
/// 100-link robot with visuals and collisions has ~2,000).
pub const MAX_XML_ELEMENTS: usize = 100_000;

/// The 1-based line where the nesting of elements in `text` first exceeds
/// [`MAX_XML_DEPTH`] or their number [`MAX_XML_ELEMENTS`], or where a
/// name has an empty namespace prefix, and which, by one linear scan: start tags deepen, end tags and `/>` return; comments,
/// `<?…?>`, `<!…>` and quoted attribute values are skipped. Malformed XML
/// is left to the parser.
fn too_large(text: &str) -> Option<(usize, String)> {
    let b = text.as_bytes();
    let (mut i, mut depth, mut line, mut elements) = (0usize, 0usize, 1usize, 0usize);
    let skip_to = |from: usize, pat: &[u8]| -> usize {
        b[from..]
            .windows(pat.len())
            .position(|w| w == pat)
            .map_or(b.len(), |p| from + p + pat.len())
    };
    while i < b.len() {
        match b[i] {
            b'\n' => line += 1,
            b'<' if b[i..].starts_with(b"<!--") => {
                let end = skip_to(i + 4, b"-->");
                line += b[i..end].iter().filter(|&&c| c == b'\n').count();
                i = end;
                continue;
            }
            b'<' if matches!(b.get(i + 1), Some(b'?' | b'!')) => {
                let end = skip_to(i + 1, b">");
                line += b[i..end].iter().filter(|&&c| c == b'\n').count();
                i = end;
                continue;
            }
            b'<' if b.get(i + 1) == Some(&b'/') => depth = depth.saturating_sub(1),
            b'<' if matches!(b.get(i + 1), Some(b'"' | b'\'')) => {
                // Not a name; RustyXML 0.3 takes it for one (and a namespace
                // declared on it panics its formatter).
                return Some((line, "an XML element name starting with a quote".into()));
            }
            b'<' => {
                // A start tag: to its '>', past quoted values.
                let mut j = i + 1;
                let mut quote = None;
                while j < b.len() {
                    match (quote, b[j]) {
                        (None, q @ (b'"' | b'\'')) => quote = Some(q),
                        (Some(q), c) if c == q => quote = None,
                        (None, b'>') => break,
                        // A name with an empty namespace prefix (`:a`): not
                        // namespace-well-formed, and RustyXML 0.3 panics on
                        // it when a default namespace is declared.
                        (None, b':')
                            if matches!(b[j - 1], b'<' | b'"' | b'\'')
                                || b[j - 1].is_ascii_whitespace() =>
                        {
                            return Some((
                                line,
                                "an XML name with an empty namespace prefix (':')".into(),
                            ));
                        }
                        (_, b'\n') => line += 1,
                        _ => {}
                    }
                    j += 1;
                }
                elements += 1;
                if elements > MAX_XML_ELEMENTS {
                    return Some((line, format!("more than {MAX_XML_ELEMENTS} XML elements")));
                }
                if b.get(j.wrapping_sub(1)) != Some(&b'/') {
                    depth += 1;
                    if depth > MAX_XML_DEPTH {
                        return Some((
                            line,
                            format!("XML elements nested more than {MAX_XML_DEPTH} deep"),
                        ));
                    }
                }
                i = j + 1;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    None
}

/// `urdf_rs::read_from_string`, with its XML parser's panics (RustyXML
/// 0.3 `expect`s a namespace prefix for every namespaced attribute, e.g.
/// `<t xmlns="i" :a=""/>`, found by fuzzing) turned into an error: a
/// hostile file is an error, never an abort. The caller scans the text
/// with [`too_large`] first (its recursion is bounded there).
///
/// # Errors
/// "not a valid URDF: …", one line.
pub(crate) fn read_urdf(text: &str) -> Result<urdf_rs::Robot, String> {
    match std::panic::catch_unwind(|| urdf_rs::read_from_string(text)) {
        Ok(Ok(urdf)) => Ok(urdf),
        Ok(Err(e)) => Err(format!("not a valid URDF: {e}")),
        Err(panic) => {
            let why = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown".into());
            Err(format!("not a valid URDF: its XML parser failed ({why})"))
        }
    }
}

/// How a chain joint moves, as the URDF says (the core's [`JointKind`] does
/// not tell revolute from continuous).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UrdfJointKind {
    /// `revolute`: rotation with limits; value in rad.
    Revolute,
    /// `continuous`: rotation without limits; value in rad.
    Continuous,
    /// `prismatic`: translation; value in m.
    Prismatic,
}

impl UrdfJointKind {
    /// The core's kind (continuous joints are revolute).
    pub fn chain_kind(self) -> JointKind {
        match self {
            UrdfJointKind::Revolute | UrdfJointKind::Continuous => JointKind::Revolute,
            UrdfJointKind::Prismatic => JointKind::Prismatic,
        }
    }

    /// Whether the joint value is an angle (revolute or continuous).
    pub fn is_angular(self) -> bool {
        !matches!(self, UrdfJointKind::Prismatic)
    }
}

/// Position limits of a joint, in rad or m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    /// Lower limit.
    pub lower: f64,
    /// Upper limit (`> lower`).
    pub upper: f64,
}

/// A movable joint off the chain whose subtree hangs from a moving body but
/// is left out of its [`crate::robot::LinkInertia`] (see the module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct OffChainBranch {
    /// The off-chain joint.
    pub joint: String,
    /// The link it hangs from (part of the moving body of chain joint `chain_joint`).
    pub parent_link: String,
    /// Index of the chain joint whose moving body carries `parent_link`.
    pub chain_joint: usize,
    /// Total mass of the subtree below `joint` \[kg\].
    pub mass_kg: f64,
}

/// The root link `robcal calibrate --output` adds above the robot (the
/// measurement frame); a URDF that has it as its root, on one fixed joint,
/// defaults `base_link` to the link below it.
pub const MEASUREMENT_FRAME: &str = "measurement_frame";

/// A robot read from a URDF: the chain from `base_link` to `tip_link` and
/// what the chain type does not hold.
#[derive(Debug, Clone, PartialEq)]
pub struct Robot {
    /// `<robot name>`.
    pub name: String,
    /// The URDF file (as given; used in error messages).
    pub file: PathBuf,
    /// Base frame of the chain.
    pub base_link: String,
    /// Tip frame of the chain (markers and the load are given in it).
    pub tip_link: String,
    /// Geometry and link inertia; joint values in rad (revolute) or m (prismatic).
    pub chain: Chain<f64, MAX_JOINTS>,
    /// URDF name of each movable joint, base to tip (chain order).
    pub joint_names: Vec<String>,
    /// URDF kind of each movable joint, chain order.
    pub joint_kinds: Vec<UrdfJointKind>,
    /// URDF position limits of each movable joint, chain order; `None` for
    /// continuous joints and for joints whose `<limit>` gives no range.
    pub limits: Vec<Option<JointLimits>>,
    /// Movable joints off the chain hanging from moving bodies, in document order.
    pub off_chain: Vec<OffChainBranch>,
    /// The links the chain ends at: `tip_link` first, then every other
    /// link a marker is fixed to (data contract 7.1), once each. More than
    /// one makes the chain a tree.
    pub end_links: Vec<String>,
    /// Where each of [`Robot::end_links`] is fixed (`ends[0]` is the
    /// chain's own tip).
    pub ends: Vec<End<f64>>,
}

impl Robot {
    /// Gives every joint whose moving body has no mass (no `<inertial>` on
    /// its child link or the links fixed to it) `mass_kg` at the origin of
    /// its frame: an assumed mass model (setup `assumed_link_mass_kg`) for
    /// a URDF without one. Joints with a mass keep theirs.
    pub fn assume_link_mass(&mut self, mass_kg: f64) {
        for j in self.chain.joints_mut() {
            if j.link.is_none() {
                j.link = Some(crate::robot::LinkInertia {
                    mass_kg,
                    com_m: nalgebra::Vector3::zeros(),
                });
            }
        }
    }

    /// Reads `path` and extracts the chain from `base_link` to `tip_link`.
    ///
    /// `base_link = None` means the URDF's root link (the one link that is
    /// no joint's child); `tip_link = None` means the one leaf link below the
    /// base. Either is an error when it is not unique.
    ///
    /// # Errors
    /// See the module doc; the error names `path`.
    pub fn load(
        path: impl AsRef<Path>,
        base_link: Option<&str>,
        tip_link: Option<&str>,
    ) -> Result<Self, InputError> {
        Self::load_tree(path, base_link, tip_link, &[])
    }

    /// As [`Robot::load`], the chain also ending at each of `marker_links`
    /// (data contract 7.1): every path from `base_link` to `tip_link` and to
    /// these links, a joint shared by several paths once. Links on the path
    /// to the tip add nothing but an end; links on other branches make the
    /// chain a tree ([`crate::robot::Chain::push_child`]).
    ///
    /// # Errors
    /// See the module doc; also a marker link that is not a link of the
    /// robot or not below `base_link`.
    pub fn load_tree(
        path: impl AsRef<Path>,
        base_link: Option<&str>,
        tip_link: Option<&str>,
        marker_links: &[&str],
    ) -> Result<Self, InputError> {
        let path = path.as_ref();
        let text = crate::io::input::read_text(path, "the URDF", crate::io::input::MAX_URDF_BYTES)?;
        Self::parse_tree(&text, path, base_link, tip_link, marker_links)
    }

    /// As [`Robot::load`], from the URDF text; `file` names it in errors.
    ///
    /// # Errors
    /// See the module doc.
    pub fn parse(
        text: &str,
        file: impl Into<PathBuf>,
        base_link: Option<&str>,
        tip_link: Option<&str>,
    ) -> Result<Self, InputError> {
        Self::parse_tree(text, file, base_link, tip_link, &[])
    }

    /// As [`Robot::load_tree`], from the URDF text; `file` names it in errors.
    ///
    /// # Errors
    /// See [`Robot::load_tree`].
    pub fn parse_tree(
        text: &str,
        file: impl Into<PathBuf>,
        base_link: Option<&str>,
        tip_link: Option<&str>,
        marker_links: &[&str],
    ) -> Result<Self, InputError> {
        let ctx = Ctx {
            file: file.into(),
            text,
        };
        if let Some((line, what)) = too_large(text) {
            return Err(ctx.err(ErrorKind::Syntax, what).at_line(line));
        }
        let urdf = read_urdf(text).map_err(|e| ctx.err(ErrorKind::Syntax, e))?;
        Tree::new(&urdf, &ctx)?.robot(&urdf, &ctx, base_link, tip_link, marker_links)
    }

    /// Number of movable joints.
    pub fn dof(&self) -> usize {
        self.joint_names.len()
    }

    /// Chain index of the movable joint named `name`.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joint_names.iter().position(|n| n == name)
    }

    /// Index into [`Robot::end_links`] of `link` (`None`: `tip_link`).
    pub fn end_index(&self, link: Option<&str>) -> Option<usize> {
        match link {
            None => Some(0),
            Some(l) => self.end_links.iter().position(|e| e == l),
        }
    }

    /// The chain ending at each of [`Robot::ends`], in that order: the chain
    /// of the markers on each link (`[0]`: [`Robot::chain`] itself).
    pub fn chains(&self) -> Vec<Chain<f64, MAX_JOINTS>> {
        // The ends were built from this chain: they fit.
        self.ends
            .iter()
            .map(|e| {
                self.chain
                    .with_tip(e)
                    .unwrap_or_else(|_| self.chain.clone())
            })
            .collect()
    }
}

pub(super) struct Ctx<'a> {
    pub(super) file: PathBuf,
    pub(super) text: &'a str,
}

impl Ctx<'_> {
    pub(super) fn err(&self, kind: ErrorKind, message: impl Into<String>) -> InputError {
        InputError::new(self.file.clone(), kind, message)
    }

    /// An error about element `<tag name="name">`, at its line if found.
    pub(super) fn err_at(
        &self,
        tag: &str,
        name: &str,
        kind: ErrorKind,
        message: String,
    ) -> InputError {
        let e = self.err(kind, format!("{tag} '{name}': {message}"));
        match element_line(self.text, tag, name) {
            Some(line) => e.at_line(line),
            None => e,
        }
    }
}

/// Line of the first `<tag ... name="name"` in `text`.
fn element_line(text: &str, tag: &str, name: &str) -> Option<usize> {
    nth_element_line(text, tag, name, 0)
}

/// Line of the `n`-th (0-based) `<tag ... name="name"` in `text`.
pub(super) fn nth_element_line(text: &str, tag: &str, name: &str, n: usize) -> Option<usize> {
    let mut seen = 0;
    for quote in ['"', '\''] {
        let pattern = format!("name={quote}{name}{quote}");
        for (at, _) in text.match_indices(&pattern) {
            let Some(lt) = text[..at].rfind('<') else {
                continue;
            };
            let element = &text[lt + 1..at];
            if element.starts_with(tag)
                && element[tag.len()..].starts_with(char::is_whitespace)
                && !element.contains('>')
            {
                if seen == n {
                    return Some(crate::io::error::line_of_offset(text, lt));
                }
                seen += 1;
            }
        }
    }
    None
}

pub(super) fn pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p.xyz[0], p.xyz[1], p.xyz[2]),
        UnitQuaternion::from_euler_angles(p.rpy[0], p.rpy[1], p.rpy[2]),
    )
}

pub(super) fn finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

mod tree;
use tree::Tree;

#[cfg(test)]
mod tests {
    const INERTIA: &str = "<inertia ixx=\"0\" ixy=\"0\" ixz=\"0\" iyy=\"0\" iyz=\"0\" izz=\"0\"/>";

    /// Three revolute joints; the middle one's child link has a mass of
    /// 3 kg, and a fixed tool link (no inertial) hangs off the last.
    fn arm(inertial: &str) -> String {
        let joint = |name: &str, parent: &str, child: &str| {
            format!(
                "<joint name=\"{name}\" type=\"continuous\"><parent link=\"{parent}\"/>\
                 <child link=\"{child}\"/><origin xyz=\"0 0 0.5\" rpy=\"0.3 0 0\"/>\
                 <axis xyz=\"0 1 0\"/></joint>"
            )
        };
        format!(
            "<robot name=\"r\"><link name=\"base\"/><link name=\"a\"{inertial}\
             <link name=\"b\"><inertial><mass value=\"3\"/>\
             <origin xyz=\"0.1 0 0.2\"/>{INERTIA}</inertial></link><link name=\"c\"/>\
             <link name=\"tool\"/>{}{}{}<joint name=\"t\" type=\"fixed\">\
             <parent link=\"c\"/><child link=\"tool\"/></joint></robot>",
            joint("j1", "base", "a"),
            joint("j2", "a", "b"),
            joint("j3", "b", "c"),
        )
    }

    /// An assumed mass is the URDF's `<inertial>` of that mass at the
    /// joint frame's origin, on every moving body without a mass; a body
    /// with a mass keeps it.
    #[test]
    fn an_assumed_link_mass_is_an_inertial_at_the_joint_origin() {
        let parse = |inertial: &str| {
            crate::io::urdf::Robot::parse(&arm(inertial), "arm.urdf", Some("base"), Some("tool"))
                .expect("a valid URDF")
        };
        let mut assumed = parse("/>");
        assumed.assume_link_mass(2.0);
        let mut explicit = parse(&format!(
            "><inertial><mass value=\"2\"/>{INERTIA}</inertial></link>"
        ));
        let j = explicit.chain.joints_mut();
        assert!(j[2].link.is_none(), "c and tool have no mass");
        j[2].link = Some(crate::robot::LinkInertia {
            mass_kg: 2.0,
            com_m: nalgebra::Vector3::zeros(),
        });
        assert_eq!(assumed.chain, explicit.chain);
        let b = assumed.chain.joints()[1].link.expect("b's own mass");
        assert_eq!(b.mass_kg, 3.0);
        assert!((b.com_m - nalgebra::Vector3::new(0.1, 0.0, 0.2)).norm() < 1e-15);
    }

    /// The parser's panic on an empty prefix (which the pre-scan refuses
    /// before it gets here) is an error, not an abort.
    #[test]
    fn a_panic_of_the_xml_parser_is_an_error() {
        let e = crate::io::urdf::read_urdf("<t xmlns=\"i\" :=\"\"/>").unwrap_err();
        assert!(e.contains("XML parser failed"), "{e}");
    }
}
