//! A stable fingerprint of a kinematic chain: a saved model answers only for the robot it
//! learned, and a cached collision model is used only for the robot it was computed from.

use crate::core::input_file::fnv;

use super::KinematicChain;

impl KinematicChain {
    /// A stable fingerprint of the chain (FNV-1a over its joints, limits and tip): the same
    /// robot description gives the same string on every machine.
    pub fn fingerprint(&self) -> String {
        let chain = self;
        let mut text = format!(
            "tip {} {:?};",
            chain.links[chain.tip_link], chain.tip_offset
        );
        let tips = chain.tips();
        if tips.len() > 1 {
            for (l, p) in tips {
                text += &format!("tips {} {:?};", chain.links[l], p);
            }
        }
        for j in &chain.joints {
            let (r, p, y) = j.origin.rotation.euler_angles();
            let t = j.origin.translation.vector;
            text += &format!(
                "{} {:?} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:?} {:?} {:?};",
                j.name,
                j.kind,
                t.x,
                t.y,
                t.z,
                r,
                p,
                y,
                j.axis.as_slice(),
                j.limits,
                j.mimic.map(|m| (m.leader, m.multiplier, m.offset))
            );
        }
        fnv(text.as_bytes())
    }
}
