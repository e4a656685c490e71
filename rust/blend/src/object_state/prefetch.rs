//! Prefetching an object's state before it is read again.
//!
//! A read walks linked lists: the modifiers, each Geometry Nodes modifier's ID properties, the
//! mesh's vertex groups; one dependent load after another. In the frame handler, right after
//! Blender's evaluation, nearly each of them misses the cache (9–11 µs a character against 3.4
//! read again at once). So a read keeps where it went, and the next read of the same object
//! first asks the CPU for all of those lines together, as the pose reader does
//! (`pose/prefetch.rs`). A prefetch is only a hint: a stale address (the object edited since)
//! never faults and never changes what is read.

use super::ObjectStateLayout;
use crate::memory::prefetch;

/// Where one read of an object's state went (see the module), for the next read of it.
#[derive(Clone, Debug, Default)]
pub struct StateHints {
    /// Each struct visited, its [`Kind`] in the low bits of its address.
    visits: Vec<usize>,
}

/// What a visited address is: which of its fields a read looks at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    Object = 0,
    Modifier = 1,
    Property = 2,
    Mesh = 3,
    VertexGroup = 4,
    /// A string's or an array's bytes (their first line).
    Bytes = 5,
}

const KIND_BITS: usize = 0b111;

/// Visits kept at most: a character with many vertex groups or inputs keeps hints for the
/// first of them (a few KB at most an object).
const MAX_VISITS: usize = 512;

impl StateHints {
    /// Prefetches the fields of every struct the last read visited.
    pub(super) fn prefetch(&self, l: &ObjectStateLayout) {
        let object = [l.id_name, l.object_type, l.object_mode, l.object_data, l.object_modifiers];
        let modifier = [
            l.modifier_next,
            l.modifier_type,
            l.modifier_flag,
            l.modifier_name.0,
            l.nodes_group,
            l.nodes_properties,
            l.modifier_system_properties.unwrap_or(l.modifier_next),
            l.armature_object,
            l.armature_group.0,
        ];
        let property =
            [l.property_next, l.property_type, l.property_name.0, l.property_val, l.property_group, l.property_len];
        for &v in &self.visits {
            let at = v & !KIND_BITS;
            let fields: &[usize] = match v & KIND_BITS {
                0 => &object,
                1 => &modifier,
                2 => &property,
                3 => &[l.mesh_groups],
                4 => &[l.group_next, l.group_name.0],
                _ => &[0],
            };
            fields.iter().for_each(|&f| prefetch(at + f));
        }
    }

    /// A new read starts.
    pub(super) fn clear(&mut self) {
        self.visits.clear();
    }

    /// The read visited the struct (or bytes) at `address`, a `kind`.
    pub(super) fn visited(&mut self, address: usize, kind: Kind) {
        if self.visits.len() < MAX_VISITS && address != 0 {
            // (Masking an unaligned address keeps it in the same line.)
            self.visits.push(address & !KIND_BITS | kind as usize);
        }
    }

    /// How many structs the last read visited (kept at most [`MAX_VISITS`]).
    pub fn len(&self) -> usize {
        self.visits.len()
    }

    pub fn is_empty(&self) -> bool {
        self.visits.is_empty()
    }
}
