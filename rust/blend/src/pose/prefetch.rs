//! Prefetching a pose before it is read again.
//!
//! A read walks an armature's channel list: one dependent load after another (a channel's
//! `next`, its bone, the bone's flag). Inside Blender's evaluation, which has just written the
//! pose on its other threads, nearly each of them misses the cache: the Rigify rig's 706
//! channels took 80 µs there against 12 µs read again at once. So a read keeps where it went,
//! and the next read of the same armature first asks the CPU for all of those lines together.
//! A prefetch is only a hint: a stale address (the rig edited since) never faults and never
//! changes what is read.

use super::{BoneLink, PoseLayout};
use crate::memory::prefetch;

/// Where one read of an armature's pose went (see the module), for the next read of it.
#[derive(Clone, Debug, Default)]
pub struct ReadHints {
    visits: Vec<Visit>,
}

#[derive(Clone, Copy, Debug)]
struct Visit {
    channel: usize,
    /// Its bone, or 0 where the read does not look at bones.
    bone: usize,
    /// The read takes the channel's matrix and, with a bone, the bone's rest data.
    whole: bool,
}

impl ReadHints {
    /// Prefetches what the last read visited: first the lines of the walk itself, then the
    /// data of the channels it read whole.
    pub(super) fn prefetch(&self, layout: &PoseLayout) {
        let link = match layout.bone_link {
            BoneLink::Pointer { chan_bone } => chan_bone,
            BoneLink::ByName { .. } => layout.chan_name,
        };
        for v in &self.visits {
            prefetch(v.channel + layout.chan_next);
            prefetch(v.channel + link);
            if v.bone != 0 {
                prefetch(v.bone + layout.bone_flag);
                if let BoneLink::ByName { bone_next, childbase_first, .. } = layout.bone_link {
                    // (The bone tree is walked by name first.)
                    prefetch(v.bone + bone_next);
                    prefetch(v.bone + childbase_first);
                    prefetch(v.bone + layout.bone_name);
                }
            }
        }
        let channel_fields = [layout.chan_name, layout.chan_mat, layout.chan_mat + 63, layout.runtime_segments];
        let bone_fields = [
            layout.bone_name,
            layout.bone_arm_mat,
            layout.bone_arm_mat + 63,
            layout.bone_head,
            layout.bone_tail,
            layout.bone_length,
            layout.bone_dist,
            layout.bone_weight,
            layout.bone_rad_head,
            layout.bone_rad_tail,
            layout.bone_segments,
            layout.bone_mapping_mode,
        ];
        for v in self.visits.iter().filter(|v| v.whole) {
            channel_fields.iter().for_each(|&f| prefetch(v.channel + f));
            if v.bone != 0 {
                bone_fields.iter().for_each(|&f| prefetch(v.bone + f));
            }
        }
    }

    /// A new read starts.
    pub(super) fn clear(&mut self) {
        self.visits.clear();
    }

    /// The read visited `channel` (and its `bone`, or 0), and read it `whole` or not.
    pub(super) fn visited(&mut self, channel: usize, bone: usize, whole: bool) {
        self.visits.push(Visit { channel, bone, whole });
    }
}
