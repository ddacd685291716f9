//! The URDF's link tree: who is whose parent and child, the chain from the
//! base to the tip with fixed joints folded in, and the mass of each moving
//! body (see the module docs of [`super`]).

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Vector3};

use crate::io::urdf::{
    finite, nth_element_line, pose, Ctx, JointLimits, OffChainBranch, Robot, UrdfJointKind,
    MAX_JOINTS,
};
use crate::io::{error::ErrorKind, error::InputError};
use crate::robot::{Chain, End, Joint, LinkInertia};

/// The link tree: who is whose parent and child.
pub(super) struct Tree<'u> {
    links: HashMap<&'u str, &'u urdf_rs::Link>,
    parent_joint: HashMap<&'u str, &'u urdf_rs::Joint>,
    child_joints: HashMap<&'u str, Vec<&'u urdf_rs::Joint>>,
}

impl<'u> Tree<'u> {
    pub(super) fn new(urdf: &'u urdf_rs::Robot, ctx: &Ctx<'_>) -> Result<Self, InputError> {
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
        let mut joint_names = std::collections::HashSet::new();
        for joint in &urdf.joints {
            // The CSV has one column per joint name: a second joint of the
            // same name could never be given a value.
            if !joint_names.insert(joint.name.as_str()) {
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
        // (Left in, the walks down the tree would never end.) Each walk
        // stops at a link already known to reach a root: linear in links.
        let mut reaches_root: std::collections::HashSet<&str> = std::collections::HashSet::new();
        for link in &urdf.links {
            let mut at = link.name.as_str();
            let mut walked = Vec::new();
            let mut on_walk = std::collections::HashSet::new();
            let mut looped = None;
            while !reaches_root.contains(at) {
                if !on_walk.insert(at) {
                    looped = parent_joint.get(at);
                    break;
                }
                walked.push(at);
                match parent_joint.get(at) {
                    Some(j) => at = j.parent.link.as_str(),
                    None => break,
                }
            }
            if looped.is_none() {
                reaches_root.extend(walked);
            }
            if let Some(joint) = looped {
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
            // A URDF robcal wrote: the robot's own root is below the
            // measurement frame it added.
            [root] if *root == crate::io::urdf::MEASUREMENT_FRAME => match self.children(root) {
                [j] if j.joint_type == urdf_rs::JointType::Fixed => Ok(j.child.link.as_str()),
                _ => Ok(root),
            },
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

    pub(super) fn robot(
        &self,
        urdf: &'u urdf_rs::Robot,
        ctx: &Ctx<'_>,
        base_link: Option<&str>,
        tip_link: Option<&str>,
        extra_links: &[&str],
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

        // The links the chain ends at: the tip first, then each other
        // marker link (data contract 7.1), once.
        let mut end_links: Vec<&str> = vec![tip];
        for &l in extra_links {
            if !self.links.contains_key(l) {
                return Err(ctx.err(
                    ErrorKind::Robot,
                    format!("marker link '{l}' is not a link of robot '{}'", urdf.name),
                ));
            }
            if !end_links.contains(&l) {
                end_links.push(l);
            }
        }

        let mut chain = Chain::<f64, MAX_JOINTS>::new();
        let mut joint_names = Vec::new();
        let mut joint_kinds = Vec::new();
        let mut limits = Vec::new();
        let mut children = Vec::new(); // child link of each movable joint
        let mut on_chain: Vec<&str> = Vec::new(); // every joint on a path
        let mut ends = Vec::new();
        for &end_link in &end_links {
            let path = self.path(base, end_link, urdf, ctx)?;
            // The movable joint the path has reached, and the fixed
            // transforms since.
            let mut last: Option<usize> = None;
            let mut pending = Isometry3::identity();
            for joint in &path {
                let name = joint.name.as_str();
                if !on_chain.contains(&name) {
                    on_chain.push(name);
                }
                if let Some(index) = joint_names.iter().position(|n| n == name) {
                    // A joint an earlier path shares.
                    last = Some(index);
                    pending = Isometry3::identity();
                    continue;
                }
                let o = &joint.origin;
                if !finite(&o.xyz.0) || !finite(&o.rpy.0) {
                    return Err(ctx.err_at(
                        "joint",
                        name,
                        ErrorKind::NonFinite,
                        format!("origin xyz {:?} rpy {:?}", o.xyz.0, o.rpy.0),
                    ));
                }
                // As the measurement reader's positions: a length no robot
                // has (1e308 m read as a joint's origin made every column
                // infinite, and the run said "parameter 0 is not
                // identifiable").
                let far = crate::io::units::MAX_POSITION_M;
                if o.xyz.0.iter().any(|v| v.abs() > far) {
                    return Err(ctx.err_at(
                        "joint",
                        name,
                        ErrorKind::InvalidValue,
                        format!(
                            "origin xyz {:?} m: beyond {far:e} m, not a robot's",
                            o.xyz.0
                        ),
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
                            format!("{other:?} joints are not supported on the chain")
                                .to_lowercase(),
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
                        format!(
                            "more than {MAX_JOINTS} movable joints from '{base}' to '{}'",
                            end_links.join("', '")
                        ),
                    ));
                }
                let a = joint.axis.xyz.0;
                if !finite(&a) {
                    return Err(ctx.err_at(
                        "joint",
                        name,
                        ErrorKind::NonFinite,
                        format!("axis {a:?}"),
                    ));
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
                let index = chain
                    .push_child(j, last)
                    .map_err(|e| ctx.err_at("joint", name, ErrorKind::Robot, e.to_string()))?;
                last = Some(index);
                joint_names.push(name.to_owned());
                joint_kinds.push(kind);
                limits.push(limit);
                children.push(joint.child.link.as_str());
            }
            if !finite(pending.translation.vector.as_slice()) {
                return Err(ctx.err(
                    ErrorKind::NonFinite,
                    format!(
                        "the fixed joints from the last movable joint to '{end_link}' overflow"
                    ),
                ));
            }
            ends.push(End {
                joint: last,
                origin: pending,
            });
        }
        if joint_names.is_empty() {
            return Err(ctx.err(
                ErrorKind::Robot,
                format!("no movable joint from base_link '{base}' to tip_link '{tip}'"),
            ));
        }
        // The tip's end was the first, its joints were pushed first.
        let chain = chain
            .with_tip(&ends[0])
            .map_err(|e| ctx.err(ErrorKind::Robot, e.to_string()))?;
        let mut chain = chain;

        // Moving bodies: each chain joint's child and everything fixed to it.
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
            end_links: end_links.iter().map(|l| (*l).to_owned()).collect(),
            ends,
        })
    }

    /// The joints (movable and fixed) from `base` down to `link`.
    fn path(
        &self,
        base: &str,
        link: &str,
        urdf: &urdf_rs::Robot,
        ctx: &Ctx<'_>,
    ) -> Result<Vec<&'u urdf_rs::Joint>, InputError> {
        let mut path = Vec::new();
        let mut at = link;
        while at != base {
            match self.parent_joint.get(at) {
                Some(joint) if path.len() <= urdf.joints.len() => {
                    path.push(*joint);
                    at = joint.parent.link.as_str();
                }
                _ => {
                    return Err(ctx.err(
                        ErrorKind::Robot,
                        format!(
                            "no path from base_link '{base}' to '{link}': \
                             '{link}' is not below '{base}'"
                        ),
                    ))
                }
            }
        }
        path.reverse();
        Ok(path)
    }
}
