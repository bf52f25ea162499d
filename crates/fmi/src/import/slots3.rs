//! The FMI 3.0 instance's table of value references: where each one's value is, looked up
//! at every step for every exchanged value.

use super::model::{Fmi3Slot, Fmi3Type};
use std::collections::HashMap;

/// Each value reference's slot: a table indexed by the reference when they are dense (an
/// FMU's usually are, and the elements' internal ones are the smallest free values), else
/// a map. The master looks every exchanged value up at every step: an index, not a hash.
pub(crate) enum Slots {
    /// The slots, and for each reference the type of a scalar that is no array element
    /// (`None` otherwise): what the one-call paths check.
    Dense(Vec<Option<Fmi3Slot>>, Vec<Option<Fmi3Type>>),
    Sparse(HashMap<u32, Fmi3Slot>),
}

impl Slots {
    pub(crate) fn new(all: Vec<(u32, Fmi3Slot)>) -> Slots {
        let max = all.iter().map(|(vr, _)| *vr as usize).max().unwrap_or(0);
        if max <= 4 * all.len() + 1024 {
            let mut t = vec![None; max + 1];
            let mut scalar = vec![None; max + 1];
            for (vr, s) in all {
                t[vr as usize] = Some(s);
                if s.len == 1 && s.vr == vr && !s.element {
                    scalar[vr as usize] = Some(s.ty);
                }
            }
            Slots::Dense(t, scalar)
        } else {
            Slots::Sparse(all.into_iter().collect())
        }
    }

    #[inline]
    pub(crate) fn get(&self, vr: u32) -> Option<Fmi3Slot> {
        match self {
            Slots::Dense(t, _) => t.get(vr as usize).copied().flatten(),
            Slots::Sparse(m) => m.get(&vr).copied(),
        }
    }

    /// The type of the scalar (no array element) at `vr`.
    #[inline]
    pub(crate) fn scalar_type(&self, vr: u32) -> Option<Fmi3Type> {
        match self {
            Slots::Dense(_, k) => k.get(vr as usize).copied().flatten(),
            Slots::Sparse(m) => m
                .get(&vr)
                .filter(|s| s.len == 1 && s.vr == vr && !s.element)
                .map(|s| s.ty),
        }
    }

    pub(crate) fn iter(&self) -> Box<dyn Iterator<Item = (u32, Fmi3Slot)> + '_> {
        match self {
            Slots::Dense(t, _) => Box::new(
                t.iter()
                    .enumerate()
                    .filter_map(|(vr, s)| s.map(|s| (vr as u32, s))),
            ),
            Slots::Sparse(m) => Box::new(m.iter().map(|(vr, s)| (*vr, *s))),
        }
    }
}
