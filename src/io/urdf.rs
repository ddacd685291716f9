//! URDF → [`Chain`]: the serial chain from `base_link` to `tip_link`, with
//! joint names, kinds and limits, and the mass properties of each moving body.
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
//! number (origin, axis, limit, mass, centre of mass) or a negative mass.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use super::{ErrorKind, InputError};
use crate::robot::{Chain, Joint, JointKind, LinkInertia};

/// Capacity of [`Robot::chain`]: the most movable joints a chain may have.
pub const MAX_JOINTS: usize = 16;

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
/// is left out of its [`LinkInertia`] (see the module doc).
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
}

impl Robot {
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
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| {
            InputError::new(path, ErrorKind::Io, format!("cannot read the URDF: {e}"))
        })?;
        Self::parse(&text, path, base_link, tip_link)
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
        let ctx = Ctx {
            file: file.into(),
            text,
        };
        let urdf = urdf_rs::read_from_string(text)
            .map_err(|e| ctx.err(ErrorKind::Syntax, format!("not a valid URDF: {e}")))?;
        Tree::new(&urdf, &ctx)?.robot(&urdf, &ctx, base_link, tip_link)
    }

    /// Number of movable joints.
    pub fn dof(&self) -> usize {
        self.joint_names.len()
    }

    /// Chain index of the movable joint named `name`.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joint_names.iter().position(|n| n == name)
    }
}

struct Ctx<'a> {
    file: PathBuf,
    text: &'a str,
}

impl Ctx<'_> {
    fn err(&self, kind: ErrorKind, message: impl Into<String>) -> InputError {
        InputError::new(self.file.clone(), kind, message)
    }

    /// An error about element `<tag name="name">`, at its line if found.
    fn err_at(&self, tag: &str, name: &str, kind: ErrorKind, message: String) -> InputError {
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
fn nth_element_line(text: &str, tag: &str, name: &str, n: usize) -> Option<usize> {
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
                    return Some(super::line_of_offset(text, lt));
                }
                seen += 1;
            }
        }
    }
    None
}

fn pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p.xyz[0], p.xyz[1], p.xyz[2]),
        UnitQuaternion::from_euler_angles(p.rpy[0], p.rpy[1], p.rpy[2]),
    )
}

fn finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

/// The link tree: who is whose parent and child.
struct Tree<'u> {
    links: HashMap<&'u str, &'u urdf_rs::Link>,
    parent_joint: HashMap<&'u str, &'u urdf_rs::Joint>,
    child_joints: HashMap<&'u str, Vec<&'u urdf_rs::Joint>>,
}

impl<'u> Tree<'u> {
    fn new(urdf: &'u urdf_rs::Robot, ctx: &Ctx<'_>) -> Result<Self, InputError> {
        let mut links = HashMap::new();
        for link in &urdf.links {
            if links.insert(link.name.as_str(), link).is_some() {
                return Err(ctx.err_at(
                    "link",
                    &link.name,
                    ErrorKind::Robot,
                    "defined twice".into(),
                ));
            }
        }
        let mut parent_joint = HashMap::new();
        let mut child_joints: HashMap<&str, Vec<&urdf_rs::Joint>> = HashMap::new();
        for (i, joint) in urdf.joints.iter().enumerate() {
            // The CSV has one column per joint name: a second joint of the
            // same name could never be given a value.
            if urdf.joints[..i].iter().any(|j| j.name == joint.name) {
                let e = ctx.err(
                    ErrorKind::Robot,
                    format!("joint '{}': defined twice", joint.name),
                );
                return Err(match nth_element_line(ctx.text, "joint", &joint.name, 1) {
                    Some(line) => e.at_line(line),
                    None => e,
                });
            }
            for (role, link) in [("parent", &joint.parent.link), ("child", &joint.child.link)] {
                if !links.contains_key(link.as_str()) {
                    return Err(ctx.err_at(
                        "joint",
                        &joint.name,
                        ErrorKind::Robot,
                        format!("{role} link '{link}' is not defined"),
                    ));
                }
            }
            if let Some(other) = parent_joint.insert(joint.child.link.as_str(), joint) {
                return Err(ctx.err_at(
                    "joint",
                    &joint.name,
                    ErrorKind::Robot,
                    format!(
                        "link '{}' is already the child of joint '{}'",
                        joint.child.link, other.name
                    ),
                ));
            }
            child_joints
                .entry(joint.parent.link.as_str())
                .or_default()
                .push(joint);
        }
        // Every link has at most one parent joint, so a loop is a link that
        // is its own ancestor: walking up from it never reaches a root.
        // (Left in, the walks down the tree would never end.)
        for link in &urdf.links {
            let mut at = link.name.as_str();
            for _ in 0..=urdf.joints.len() {
                match parent_joint.get(at) {
                    Some(j) => at = j.parent.link.as_str(),
                    None => break,
                }
            }
            if let Some(joint) = parent_joint.get(at) {
                return Err(ctx.err_at(
                    "joint",
                    &joint.name,
                    ErrorKind::Robot,
                    format!(
                        "closes a loop of links through '{}': a URDF is a tree",
                        joint.child.link
                    ),
                ));
            }
        }
        Ok(Self {
            links,
            parent_joint,
            child_joints,
        })
    }

    fn children(&self, link: &str) -> &[&'u urdf_rs::Joint] {
        self.child_joints.get(link).map_or(&[], Vec::as_slice)
    }

    fn default_base(&self, urdf: &'u urdf_rs::Robot, ctx: &Ctx<'_>) -> Result<&'u str, InputError> {
        let roots: Vec<&str> = urdf
            .links
            .iter()
            .map(|l| l.name.as_str())
            .filter(|l| !self.parent_joint.contains_key(l))
            .collect();
        match roots.as_slice() {
            [root] => Ok(root),
            _ => Err(ctx.err(
                ErrorKind::Robot,
                format!(
                    "base_link not given and the URDF has {} root links ({}): set base_link",
                    roots.len(),
                    roots.join(", ")
                ),
            )),
        }
    }

    fn default_tip(&self, base: &'u str, ctx: &Ctx<'_>) -> Result<&'u str, InputError> {
        let mut leaves = Vec::new();
        let mut stack = vec![base];
        while let Some(link) = stack.pop() {
            let children = self.children(link);
            if children.is_empty() {
                leaves.push(link);
            }
            stack.extend(children.iter().map(|j| j.child.link.as_str()));
            if leaves.len() > 1 {
                break;
            }
        }
        match leaves.as_slice() {
            [leaf] => Ok(leaf),
            _ => Err(ctx.err(
                ErrorKind::Robot,
                format!("tip_link not given and the tree below '{base}' branches: set tip_link"),
            )),
        }
    }

    /// Total mass below (and including) `link`, every joint type followed.
    fn subtree_mass(&self, link: &str, ctx: &Ctx<'_>) -> Result<f64, InputError> {
        let mut total = 0.0;
        let mut stack = vec![link];
        while let Some(l) = stack.pop() {
            total += self.mass(l, ctx)?;
            stack.extend(self.children(l).iter().map(|j| j.child.link.as_str()));
        }
        Ok(total)
    }

    fn mass(&self, link: &str, ctx: &Ctx<'_>) -> Result<f64, InputError> {
        let m = self.links[link].inertial.mass.value;
        if !m.is_finite() {
            return Err(ctx.err_at("link", link, ErrorKind::NonFinite, format!("mass {m}")));
        }
        if m < 0.0 {
            return Err(ctx.err_at(
                "link",
                link,
                ErrorKind::InvalidValue,
                format!("negative mass {m}"),
            ));
        }
        Ok(m)
    }

    fn robot(
        &self,
        urdf: &'u urdf_rs::Robot,
        ctx: &Ctx<'_>,
        base_link: Option<&str>,
        tip_link: Option<&str>,
    ) -> Result<Robot, InputError> {
        let base = match base_link {
            Some(b) => b,
            None => self.default_base(urdf, ctx)?,
        };
        for (key, link) in [("base_link", Some(base)), ("tip_link", tip_link)] {
            if let Some(link) = link {
                if !self.links.contains_key(link) {
                    return Err(ctx.err(
                        ErrorKind::Robot,
                        format!("{key} '{link}' is not a link of robot '{}'", urdf.name),
                    ));
                }
            }
        }
        let tip = match tip_link {
            Some(t) => t,
            None => self.default_tip(base, ctx)?,
        };

        // Path: walk up from the tip to the base.
        let mut path = Vec::new();
        let mut link = tip;
        while link != base {
            match self.parent_joint.get(link) {
                Some(joint) if path.len() <= urdf.joints.len() => {
                    path.push(*joint);
                    link = joint.parent.link.as_str();
                }
                _ => {
                    return Err(ctx.err(
                        ErrorKind::Robot,
                        format!(
                            "no path from base_link '{base}' to tip_link '{tip}': \
                             '{tip}' is not below '{base}'"
                        ),
                    ))
                }
            }
        }
        path.reverse();

        let mut chain = Chain::<f64, MAX_JOINTS>::new();
        let mut joint_names = Vec::new();
        let mut joint_kinds = Vec::new();
        let mut limits = Vec::new();
        let mut children = Vec::new(); // child link of each movable joint
        let mut pending = Isometry3::identity();
        for joint in &path {
            let name = joint.name.as_str();
            let o = &joint.origin;
            if !finite(&o.xyz.0) || !finite(&o.rpy.0) {
                return Err(ctx.err_at(
                    "joint",
                    name,
                    ErrorKind::NonFinite,
                    format!("origin xyz {:?} rpy {:?}", o.xyz.0, o.rpy.0),
                ));
            }
            let kind = match joint.joint_type {
                urdf_rs::JointType::Fixed => {
                    pending *= pose(o);
                    continue;
                }
                urdf_rs::JointType::Revolute => UrdfJointKind::Revolute,
                urdf_rs::JointType::Continuous => UrdfJointKind::Continuous,
                urdf_rs::JointType::Prismatic => UrdfJointKind::Prismatic,
                ref other => {
                    return Err(ctx.err_at(
                        "joint",
                        name,
                        ErrorKind::Robot,
                        format!("{other:?} joints are not supported on the chain").to_lowercase(),
                    ))
                }
            };
            if let Some(mimic) = &joint.mimic {
                return Err(ctx.err_at(
                    "joint",
                    name,
                    ErrorKind::Robot,
                    format!(
                        "mimic joint (of '{}') on the chain is not supported",
                        mimic.joint
                    ),
                ));
            }
            if joint_names.len() == MAX_JOINTS {
                return Err(ctx.err_at(
                    "joint",
                    name,
                    ErrorKind::Robot,
                    format!("more than {MAX_JOINTS} movable joints from '{base}' to '{tip}'"),
                ));
            }
            let a = joint.axis.xyz.0;
            if !finite(&a) {
                return Err(ctx.err_at("joint", name, ErrorKind::NonFinite, format!("axis {a:?}")));
            }
            // Normalizing `1e300 1e300 0` overflows its norm (the unit axis
            // came out 0): divide by the largest component first (exact in
            // direction; only ever by a factor > 1, so a tiny axis is still
            // a zero axis).
            let big = a.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            let a = if big > 1.0 { a.map(|v| v / big) } else { a };
            let mut j = Joint::from_urdf(
                Vector3::from(o.xyz.0),
                Vector3::from(o.rpy.0),
                Vector3::from(a),
                kind.chain_kind(),
            )
            .ok_or_else(|| ctx.err_at("joint", name, ErrorKind::Robot, "zero axis".into()))?;
            j.origin = pending * j.origin;
            pending = Isometry3::identity();
            // Each origin is finite, their composition need not be (two
            // fixed joints of 1e308 m).
            if !finite(j.origin.translation.vector.as_slice()) {
                return Err(ctx.err_at(
                    "joint",
                    name,
                    ErrorKind::NonFinite,
                    format!(
                        "origin {:?} m with the fixed joints before it overflows",
                        j.origin.translation.vector.as_slice()
                    ),
                ));
            }
            let limit = match kind {
                UrdfJointKind::Continuous => None,
                _ => {
                    let (lower, upper) = (joint.limit.lower, joint.limit.upper);
                    if lower.is_nan() || upper.is_nan() {
                        return Err(ctx.err_at(
                            "joint",
                            name,
                            ErrorKind::NonFinite,
                            format!("limit lower {lower} upper {upper}"),
                        ));
                    }
                    (lower.is_finite() && upper.is_finite() && lower < upper)
                        .then_some(JointLimits { lower, upper })
                }
            };
            chain
                .push(j)
                .map_err(|e| ctx.err_at("joint", name, ErrorKind::Robot, e.to_string()))?;
            joint_names.push(name.to_owned());
            joint_kinds.push(kind);
            limits.push(limit);
            children.push(joint.child.link.as_str());
        }
        if joint_names.is_empty() {
            return Err(ctx.err(
                ErrorKind::Robot,
                format!("no movable joint from base_link '{base}' to tip_link '{tip}'"),
            ));
        }
        if !finite(pending.translation.vector.as_slice()) {
            return Err(ctx.err(
                ErrorKind::NonFinite,
                format!(
                    "the fixed joints from the last movable joint to tip_link '{tip}' overflow"
                ),
            ));
        }
        chain.set_tip(pending);

        // Moving bodies: each chain joint's child and everything fixed to it.
        let on_chain: Vec<&str> = path.iter().map(|j| j.name.as_str()).collect();
        let mut off_chain = Vec::new();
        for (index, child) in children.iter().enumerate() {
            let mut mass = 0.0;
            let mut moment = Vector3::zeros();
            let mut stack = vec![(*child, Isometry3::<f64>::identity())];
            while let Some((link, frame)) = stack.pop() {
                let m = self.mass(link, ctx)?;
                let c = self.links[link].inertial.origin.xyz.0;
                if !finite(&c) {
                    return Err(ctx.err_at(
                        "link",
                        link,
                        ErrorKind::NonFinite,
                        format!("inertial origin {c:?}"),
                    ));
                }
                mass += m;
                moment += (frame * Point3::from(c)).coords * m;
                for joint in self.children(link) {
                    let child_link = joint.child.link.as_str();
                    if joint.joint_type == urdf_rs::JointType::Fixed {
                        let o = &joint.origin;
                        if !finite(&o.xyz.0) || !finite(&o.rpy.0) {
                            return Err(ctx.err_at(
                                "joint",
                                &joint.name,
                                ErrorKind::NonFinite,
                                format!("origin xyz {:?} rpy {:?}", o.xyz.0, o.rpy.0),
                            ));
                        }
                        let next = frame * pose(o);
                        if !finite(next.translation.vector.as_slice()) {
                            return Err(ctx.err_at(
                                "joint",
                                &joint.name,
                                ErrorKind::NonFinite,
                                "origin with the fixed joints before it overflows".into(),
                            ));
                        }
                        stack.push((child_link, next));
                    } else if !on_chain.contains(&joint.name.as_str()) {
                        off_chain.push(OffChainBranch {
                            joint: joint.name.clone(),
                            parent_link: link.to_owned(),
                            chain_joint: index,
                            mass_kg: self.subtree_mass(child_link, ctx)?,
                        });
                    }
                }
            }
            // Finite masses and centres of mass can still overflow the sum
            // or the mass moment (1e300 kg at 1e10 m).
            if !mass.is_finite() || !finite(moment.as_slice()) {
                return Err(ctx.err_at(
                    "link",
                    child,
                    ErrorKind::NonFinite,
                    format!(
                        "the mass ({mass} kg) or mass moment of the body moved by joint '{}' \
                         overflows",
                        joint_names[index]
                    ),
                ));
            }
            if mass > 0.0 {
                chain.joints_mut()[index].link = Some(LinkInertia {
                    mass_kg: mass,
                    com_m: moment / mass,
                });
            }
        }
        let order: HashMap<&str, usize> = urdf
            .joints
            .iter()
            .enumerate()
            .map(|(i, j)| (j.name.as_str(), i))
            .collect();
        off_chain.sort_by_key(|b| order[b.joint.as_str()]);

        Ok(Robot {
            name: urdf.name.clone(),
            file: ctx.file.clone(),
            base_link: base.to_owned(),
            tip_link: tip.to_owned(),
            chain,
            joint_names,
            joint_kinds,
            limits,
            off_chain,
        })
    }
}
