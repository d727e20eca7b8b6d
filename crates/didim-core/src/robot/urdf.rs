//! A [`Robot`] from a URDF document, parsed by `urdf-rs`: the actuated joints from the root link
//! down, fixed joints (and joints not picked) merged into the body before them, each link's
//! inertia moved into its body's joint frame.

use std::collections::HashMap;

use nalgebra::{Matrix3, Vector3};

use super::spatial::{self, Pose};
use super::{Joint, JointKind, Robot, BODY_PARAMS};
use crate::error::{invalid, Result};

fn pose_of(p: &urdf_rs::Pose) -> Pose {
    Pose {
        rotation: spatial::rpy(p.rpy[0], p.rpy[1], p.rpy[2]),
        translation: Vector3::new(p.xyz[0], p.xyz[1], p.xyz[2]),
    }
}

/// The inertial parameters of `link` placed at `at` in the body's frame.
fn link_params(link: &urdf_rs::Link, at: &Pose) -> [f64; BODY_PARAMS] {
    let inertial = &link.inertial;
    let local = at.compose(&pose_of(&inertial.origin));
    let i = &inertial.inertia;
    let ic = Matrix3::new(i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz);
    let ic_body = local.rotation * ic * local.rotation.transpose();
    spatial::params_of(inertial.mass.value, &local.translation, &ic_body)
}

struct Walk<'a> {
    links: HashMap<&'a str, &'a urdf_rs::Link>,
    children: HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
    picked: Option<&'a [String]>,
    out: Vec<Joint>,
    /// The body each actuated joint follows (None: the fixed base).
    parents: Vec<Option<usize>>,
}

impl<'a> Walk<'a> {
    fn actuated(&self, j: &urdf_rs::Joint) -> Result<Option<JointKind>> {
        let kind = match j.joint_type {
            urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => JointKind::Revolute,
            urdf_rs::JointType::Prismatic => JointKind::Prismatic,
            urdf_rs::JointType::Fixed => return Ok(None),
            ref other => {
                if self.picked.is_some_and(|p| !p.contains(&j.name)) {
                    return Ok(None);
                }
                return Err(invalid!(
                    "joint {} is {:?}: didim models chains of revolute and prismatic joints; leave it out with joints=[...]",
                    j.name,
                    other
                ));
            }
        };
        Ok(match self.picked {
            Some(p) if !p.contains(&j.name) => None, // locked at zero
            _ => Some(kind),
        })
    }

    /// Walks the subtree of `link`, placed at `at` in the frame of `body`.
    fn visit(&mut self, link: &'a str, at: Pose, body: Option<usize>) -> Result<()> {
        let l = self
            .links
            .get(link)
            .ok_or_else(|| invalid!("the URDF names link {link} but does not define it"))?;
        if let Some(b) = body {
            let p = link_params(l, &at);
            for (x, y) in self.out[b].inertia.iter_mut().zip(p) {
                *x += y;
            }
        }
        let joints = self.children.get(link).cloned().unwrap_or_default();
        for j in joints {
            let placed = at.compose(&pose_of(&j.origin));
            match self.actuated(j)? {
                // fixed, or not picked: locked at zero, where a joint's own motion is the identity
                None => self.visit(&j.child.link, placed, body)?,
                Some(kind) => {
                    let axis = Vector3::new(j.axis.xyz[0], j.axis.xyz[1], j.axis.xyz[2]);
                    if axis.norm() <= 0.0 || !axis.norm().is_finite() {
                        return Err(invalid!("joint {}: its axis is zero", j.name));
                    }
                    let lim = &j.limit;
                    let (lower, upper) =
                        if j.joint_type == urdf_rs::JointType::Continuous || lim.lower >= lim.upper {
                            (f64::NEG_INFINITY, f64::INFINITY)
                        } else {
                            (lim.lower, lim.upper)
                        };
                    self.out.push(Joint {
                        name: j.name.clone(),
                        kind,
                        axis: axis.normalize(),
                        placement_rotation: placed.rotation,
                        placement_translation: placed.translation,
                        inertia: [0.0; BODY_PARAMS],
                        lower,
                        upper,
                        velocity_limit: if lim.velocity > 0.0 {
                            lim.velocity
                        } else {
                            f64::INFINITY
                        },
                        effort_limit: if lim.effort > 0.0 {
                            lim.effort
                        } else {
                            f64::INFINITY
                        },
                    });
                    self.parents.push(body);
                    let me = self.out.len() - 1;
                    self.visit(&j.child.link, Pose::identity(), Some(me))?;
                }
            }
        }
        Ok(())
    }
}

/// The deepest element nesting a URDF may have: a robot description is a few levels deep (robot,
/// link, inertial, inertia); a document nested deeper is not one, and its parse would exhaust the
/// stack.
pub const MAX_XML_DEPTH: usize = 64;

/// The most links a URDF may define: the walk from the root recurses once per link of a chain, and a chain of
/// 2,000 links overflowed the stack (a segfault); robots have tens.
pub const MAX_LINKS: usize = 512;

/// A link's inertia is refused when a principal moment is negative by more than this share of the largest inertia
/// entry of the robot's links (rounding in a URDF's small links stays far below it).
pub const INERTIA_RTOL: f64 = 1e-6;

/// The nesting depth of the XML elements of `text` (a scan of its tags: comments, processing
/// instructions, declarations and CDATA are skipped; self-closing tags do not nest).
pub(super) fn xml_depth(text: &str) -> usize {
    let b = text.as_bytes();
    let (mut i, mut depth, mut deepest) = (0usize, 0usize, 0usize);
    while i < b.len() {
        if b[i] != b'<' {
            i += 1;
            continue;
        }
        let rest = &text[i..];
        let skip_to = |end: &str| rest.find(end).map_or(b.len(), |k| i + k + end.len());
        if rest.starts_with("<!--") {
            i = skip_to("-->");
        } else if rest.starts_with("<![CDATA[") {
            i = skip_to("]]>");
        } else if rest.starts_with("<?") {
            i = skip_to("?>");
        } else if rest.starts_with("<!") {
            i = skip_to(">");
        } else if rest.starts_with("</") {
            depth = depth.saturating_sub(1);
            i = skip_to(">");
        } else {
            let end = skip_to(">");
            if !text[i..end].ends_with("/>") {
                depth += 1;
                deepest = deepest.max(depth);
            }
            i = end;
        }
    }
    deepest
}

/// The document's links and joints form one tree: links and joints named once, every joint between
/// two defined links, each link the child of one joint at most and none of its own, every link
/// reached from the one root (returned); the error names the link or the joint and what to change.
fn check_tree(doc: &urdf_rs::Robot) -> Result<&str> {
    if doc.links.is_empty() {
        return Err(invalid!(
            "the URDF defines no link: a robot is <link> elements joined by <joint> elements"
        ));
    }
    if doc.links.len() > MAX_LINKS {
        return Err(invalid!(
            "the URDF defines {} links: didim reads robots of up to {MAX_LINKS} links (an arm has tens); is this a \
             generated or concatenated file?",
            doc.links.len()
        ));
    }
    let mut seen: HashMap<&str, usize> = HashMap::new();
    for l in &doc.links {
        if seen.insert(l.name.as_str(), 0).is_some() {
            return Err(invalid!(
                "link {} is defined twice: each <link> needs its own name",
                l.name
            ));
        }
    }
    let mut names: HashMap<&str, ()> = HashMap::new();
    let mut parent_of: HashMap<&str, &str> = HashMap::new();
    for j in &doc.joints {
        if names.insert(j.name.as_str(), ()).is_some() {
            return Err(invalid!(
                "joint {} is defined twice: each <joint> needs its own name",
                j.name
            ));
        }
        for (role, link) in [("parent", &j.parent.link), ("child", &j.child.link)] {
            if !seen.contains_key(link.as_str()) {
                return Err(invalid!(
                    "joint {}'s {role} link {link} is not defined: add <link name=\"{link}\"> or correct the name",
                    j.name
                ));
            }
        }
        if j.parent.link == j.child.link {
            return Err(invalid!(
                "joint {} joins link {} to itself: its parent and child must be two links",
                j.name,
                j.child.link
            ));
        }
        if let Some(other) = parent_of.insert(j.child.link.as_str(), j.name.as_str()) {
            return Err(invalid!(
                "link {} is the child of two joints ({other} and {}): a URDF is a tree, each link hangs from one joint; \
                 a closed chain cannot be written in URDF (remove one of the two joints)",
                j.child.link,
                j.name
            ));
        }
    }
    // every link reached from a root: links whose joints form a loop among themselves hang from none
    let roots: Vec<&str> = doc
        .links
        .iter()
        .map(|l| l.name.as_str())
        .filter(|l| !parent_of.contains_key(l))
        .collect();
    let mut reached: std::collections::HashSet<&str> = std::collections::HashSet::new();
    let mut todo = roots.clone();
    while let Some(l) = todo.pop() {
        if reached.insert(l) {
            todo.extend(
                doc.joints
                    .iter()
                    .filter(|j| j.parent.link == l)
                    .map(|j| j.child.link.as_str()),
            );
        }
    }
    let cut: Vec<&str> = doc
        .links
        .iter()
        .map(|l| l.name.as_str())
        .filter(|l| !reached.contains(l))
        .collect();
    if !cut.is_empty() {
        return Err(invalid!(
            "the joints between links {} form a loop: a URDF is a tree from one root link (a closed chain cannot be \
             written in URDF: remove one joint of the loop)",
            cut.join(", ")
        ));
    }
    let finite = |what: String, v: &[f64]| -> Result<()> {
        match v.iter().find(|x| !x.is_finite()) {
            None => Ok(()),
            Some(x) => Err(invalid!(
                "{what} holds {x}: every number of a URDF must be finite"
            )),
        }
    };
    let pose = |p: &urdf_rs::Pose| [p.xyz[0], p.xyz[1], p.xyz[2], p.rpy[0], p.rpy[1], p.rpy[2]];
    for j in &doc.joints {
        finite(format!("joint {}'s <origin>", j.name), &pose(&j.origin))?;
        finite(
            format!("joint {}'s <axis>", j.name),
            &[j.axis.xyz[0], j.axis.xyz[1], j.axis.xyz[2]],
        )?;
    }
    for l in &doc.links {
        let i = &l.inertial;
        finite(format!("link {}'s <inertial> <origin>", l.name), &pose(&i.origin))?;
        finite(format!("link {}'s <mass>", l.name), &[i.mass.value])?;
        let t = &i.inertia;
        finite(
            format!("link {}'s <inertia>", l.name),
            &[t.ixx, t.ixy, t.ixz, t.iyy, t.iyz, t.izz],
        )?;
        if i.mass.value < 0.0 {
            return Err(invalid!(
                "link {}'s <mass> is {}: a mass is >= 0 kg",
                l.name,
                i.mass.value
            ));
        }
    }
    // an inertia matrix with a negative principal moment that matters against the robot's inertias (real URDFs carry
    // tiny links whose rounded inertias are not quite positive: Tiago's antennas, -3.5e-8 kg·m² at 1 mg)
    let tensor = |l: &urdf_rs::Link| {
        let t = &l.inertial.inertia;
        Matrix3::new(t.ixx, t.ixy, t.ixz, t.ixy, t.iyy, t.iyz, t.ixz, t.iyz, t.izz)
    };
    let largest = doc
        .links
        .iter()
        .map(|l| tensor(l).abs().max())
        .fold(0.0, f64::max);
    for l in &doc.links {
        let least = tensor(l).symmetric_eigenvalues().min();
        if least < -INERTIA_RTOL * largest {
            return Err(invalid!(
                "link {}'s <inertia> has a negative principal moment ({least:.4e} kg·m²): an inertia matrix is \
                 positive semi-definite (check the signs of ixx, iyy, izz and the size of ixy, ixz, iyz)",
                l.name
            ));
        }
    }
    match roots.as_slice() {
        [r] => Ok(r),
        _ => Err(invalid!(
            "the URDF has several root links ({}): one tree is expected",
            roots.join(", ")
        )),
    }
}

/// The text outside its XML comments (a URDF exported from xacro may keep commented-out macros).
fn without_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find("<!--") {
        out.push_str(&rest[..i]);
        match rest[i + 4..].find("-->") {
            Some(j) => rest = &rest[i + 4 + j + 3..],
            None => return out,
        }
    }
    out.push_str(rest);
    out
}

/// The name of the document's root element, past the XML declaration, comments and doctype; None when the text
/// holds no element.
fn root_element(text: &str) -> Option<&str> {
    let mut rest = text;
    loop {
        let i = rest.find('<')?;
        rest = &rest[i..];
        if let Some(r) = rest.strip_prefix("<!--") {
            rest = &r[r.find("-->")? + 3..];
        } else if rest.starts_with("<?") || rest.starts_with("<!") {
            rest = &rest[rest.find('>')? + 1..];
        } else {
            let name = &rest[1..];
            let end = name
                .find(|c: char| c.is_whitespace() || c == '>' || c == '/')
                .unwrap_or(name.len());
            return Some(&name[..end]);
        }
    }
}

pub fn parse(text: &str, picked: Option<&[String]>) -> Result<Robot> {
    let depth = xml_depth(text);
    if depth > MAX_XML_DEPTH {
        return Err(invalid!(
            "not a URDF robot description: its XML is nested {depth} elements deep (a URDF is a few levels deep)"
        ));
    }
    match root_element(text) {
        Some("robot") | None => {}
        Some("sdf") => {
            return Err(invalid!(
                "an SDF model (its root element is <sdf>), not a URDF: didim reads URDF (<robot>); convert it (e.g. \
                 with the sdformat_urdf tools) or write the URDF"
            ))
        }
        Some(other) => {
            return Err(invalid!(
                "not a URDF robot description: its root element is <{other}>, a URDF's is <robot>"
            ))
        }
    }
    let live = without_comments(text);
    if live.contains("<xacro:") || live.contains("${") {
        return Err(invalid!(
            "a xacro file (it holds xacro macros or ${{...}} expressions): expand it into a URDF first (xacro robot.urdf.xacro > robot.urdf)"
        ));
    }
    let doc = urdf_rs::read_from_string(text).map_err(|e| invalid!("not a URDF robot description: {e}"))?;
    let root = check_tree(&doc)?;
    let links: HashMap<&str, &urdf_rs::Link> = doc.links.iter().map(|l| (l.name.as_str(), l)).collect();
    let mut children: HashMap<&str, Vec<&urdf_rs::Joint>> = HashMap::new();
    for j in &doc.joints {
        children.entry(j.parent.link.as_str()).or_default().push(j);
    }
    if let Some(p) = picked {
        let known: Vec<&str> = doc.joints.iter().map(|j| j.name.as_str()).collect();
        for name in p {
            if !known.contains(&name.as_str()) {
                return Err(invalid!(
                    "the URDF has no joint {name}; its joints: {}",
                    known.join(", ")
                ));
            }
        }
    }
    let mut walk = Walk {
        links,
        children,
        picked,
        out: Vec::new(),
        parents: Vec::new(),
    };
    walk.visit(root, Pose::identity(), None)?;
    if picked.is_none() {
        if let Some(trunk) = trunk(&walk.out, &walk.parents) {
            // a chain whose end splits into short branches (a gripper's fingers): the chain, the branches locked
            let mut robot = parse(text, Some(&trunk))?;
            robot.locked = walk
                .out
                .iter()
                .map(|j| j.name.clone())
                .filter(|n| !trunk.contains(n))
                .collect();
            return Ok(robot);
        }
    }
    // a serial chain: each actuated joint follows the one before it
    for (i, p) in walk.parents.iter().enumerate() {
        let expected = if i == 0 { None } else { Some(i - 1) };
        if *p != expected {
            let after = p.map_or("the base".to_string(), |b| walk.out[b].name.clone());
            return Err(invalid!(
                "the URDF is a tree, not a serial chain: joint {} follows {after}, not {}; pick one branch with joints=[...]",
                walk.out[i].name,
                if i == 0 { "the base".to_string() } else { walk.out[i - 1].name.clone() }
            ));
        }
    }
    if let Some(p) = picked {
        let order: Vec<&str> = walk.out.iter().map(|j| j.name.as_str()).collect();
        for name in p {
            if !order.contains(&name.as_str()) {
                return Err(invalid!(
                    "joint {name} is fixed in the URDF: it cannot be actuated"
                ));
            }
        }
        if order.iter().zip(p).any(|(a, b)| *a != b.as_str()) {
            return Err(invalid!(
                "list the joints in the chain's order, from the base: {}",
                order.join(", ")
            ));
        }
    }
    // a mimic joint follows another joint's position (one motor driving both): didim's joints are each driven
    for j in &walk.out {
        if let Some(m) = doc
            .joints
            .iter()
            .find(|d| d.name == j.name)
            .and_then(|d| d.mimic.as_ref())
        {
            return Err(invalid!(
                "joint {} mimics joint {} (<mimic>): didim does not support mimic joints (one motor driving two); \
                 leave it out with joints=[...] (CLI: --joints; it is then locked at zero), or drive it on its own \
                 (remove its <mimic>)",
                j.name,
                m.joint
            ));
        }
    }
    Robot::new(&doc.name, walk.out)
}

/// The chain from the base up to the first joint with several actuated joints after it, when the
/// tree splits there into branches no longer than that chain (a gripper's fingers at the end of an
/// arm); None for a serial chain, or a tree that splits earlier (two arms on a torso, legs).
fn trunk(out: &[Joint], parents: &[Option<usize>]) -> Option<Vec<String>> {
    let children = |b: Option<usize>| (0..out.len()).filter(move |&i| parents[i] == b);
    let mut chain = Vec::new();
    let mut at: Option<usize> = None;
    loop {
        let next: Vec<usize> = children(at).collect();
        match next.as_slice() {
            [] => return None, // the tree is a chain
            [one] => {
                chain.push(*one);
                at = Some(*one);
            }
            _ => break,
        }
    }
    // the longest branch after the split
    fn depth(i: usize, parents: &[Option<usize>]) -> usize {
        1 + (0..parents.len())
            .filter(|&k| parents[k] == Some(i))
            .map(|k| depth(k, parents))
            .max()
            .unwrap_or(0)
    }
    let longest = children(at).map(|k| depth(k, parents)).max().unwrap_or(0);
    if chain.is_empty() || longest > chain.len() / 2 {
        return None;
    }
    Some(chain.iter().map(|&i| out[i].name.clone()).collect())
}
