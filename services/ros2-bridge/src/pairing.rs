//! Left and right images paired by header stamp: equal stamps, or the nearest within a
//! tolerance.
//!
//! Each topic delivers its images in stamp order, so an image is unpaired once the other
//! side has delivered one newer than its stamp plus the tolerance (its partner can no longer
//! come), or once a newer image of its own side is nearer to the other side's; an image
//! that waits while `capacity` newer ones of its side queue up behind it is unpaired too.

use std::collections::VecDeque;

/// A stereo side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The left camera.
    Left = 0,
    /// The right camera.
    Right = 1,
}

impl Side {
    /// `left` or `right`.
    pub fn name(self) -> &'static str {
        match self {
            Side::Left => "left",
            Side::Right => "right",
        }
    }
}

/// What the pairing decided, in the order it decided.
#[derive(Debug, PartialEq)]
pub enum Paired<T> {
    /// A left and a right image of one frame, stamped with the left one's stamp.
    Pair {
        /// The left image's stamp, ns.
        stamp_ns: u64,
        /// The left image.
        left: T,
        /// The right image.
        right: T,
    },
    /// An image without a partner.
    Unpaired {
        /// Its side.
        side: Side,
        /// Its stamp, ns.
        stamp_ns: u64,
        /// The image.
        item: T,
    },
}

/// Pairs images of two sides by stamp.
#[derive(Debug)]
pub struct Pairing<T> {
    tolerance_ns: u64,
    capacity: usize,
    sides: [VecDeque<(u64, T)>; 2],
}

impl<T> Pairing<T> {
    /// Pairs stamps at most `tolerance_ns` apart, each side waiting with at most `capacity`
    /// images.
    pub fn new(tolerance_ns: u64, capacity: usize) -> Self {
        Self {
            tolerance_ns,
            capacity: capacity.max(1),
            sides: [VecDeque::new(), VecDeque::new()],
        }
    }

    /// Images waiting for a partner.
    pub fn waiting(&self) -> usize {
        self.sides.iter().map(VecDeque::len).sum()
    }

    /// Takes an image of `side` stamped `stamp_ns`; appends what it settles to `out`.
    pub fn push(&mut self, side: Side, stamp_ns: u64, item: T, out: &mut VecDeque<Paired<T>>) {
        let queue = &mut self.sides[side as usize];
        // In stamp order, should a topic ever deliver out of order.
        let at = queue.partition_point(|(s, _)| *s <= stamp_ns);
        queue.insert(at, (stamp_ns, item));
        self.settle(out);
        for side in [Side::Left, Side::Right] {
            while self.sides[side as usize].len() > self.capacity {
                self.unpaired(side, out);
            }
        }
    }

    fn unpaired(&mut self, side: Side, out: &mut VecDeque<Paired<T>>) {
        if let Some((stamp_ns, item)) = self.sides[side as usize].pop_front() {
            out.push_back(Paired::Unpaired {
                side,
                stamp_ns,
                item,
            });
        }
    }

    /// Whether the second image of `side` is nearer to `stamp_ns` than its first.
    fn next_is_nearer(&self, side: Side, stamp_ns: u64) -> bool {
        let queue = &self.sides[side as usize];
        match (queue.front(), queue.get(1)) {
            (Some((first, _)), Some((second, _))) => {
                second.abs_diff(stamp_ns) < first.abs_diff(stamp_ns)
            }
            _ => false,
        }
    }

    /// Pairs and unpairs what the two fronts allow.
    fn settle(&mut self, out: &mut VecDeque<Paired<T>>) {
        loop {
            let (Some((left, _)), Some((right, _))) =
                (self.sides[0].front(), self.sides[1].front())
            else {
                return;
            };
            let (left, right) = (*left, *right);
            if left.abs_diff(right) > self.tolerance_ns {
                // The older one's partner would have come before the other's front.
                self.unpaired(
                    if left < right {
                        Side::Left
                    } else {
                        Side::Right
                    },
                    out,
                );
                continue;
            }
            if self.next_is_nearer(Side::Left, right) {
                self.unpaired(Side::Left, out);
                continue;
            }
            if self.next_is_nearer(Side::Right, left) {
                self.unpaired(Side::Right, out);
                continue;
            }
            if let (Some((stamp_ns, left)), Some((_, right))) =
                (self.sides[0].pop_front(), self.sides[1].pop_front())
            {
                out.push_back(Paired::Pair {
                    stamp_ns,
                    left,
                    right,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What `pushes` settle, as ("pair", left, right) or ("left"/"right", id, 0).
    fn run(
        tolerance: u64,
        capacity: usize,
        pushes: &[(Side, u64)],
    ) -> Vec<(&'static str, u64, u64)> {
        let mut pairing = Pairing::new(tolerance, capacity);
        let mut out = VecDeque::new();
        for (side, stamp) in pushes {
            pairing.push(*side, *stamp, *stamp, &mut out);
        }
        out.into_iter()
            .map(|p| match p {
                Paired::Pair { left, right, .. } => ("pair", left, right),
                Paired::Unpaired { side, item, .. } => (side.name(), item, 0),
            })
            .collect()
    }

    use Side::{Left as L, Right as R};

    #[test]
    fn equal_stamps_pair_whichever_side_comes_first() {
        assert_eq!(
            run(0, 4, &[(L, 10), (R, 10), (R, 20), (L, 20)]),
            [("pair", 10, 10), ("pair", 20, 20)]
        );
    }

    #[test]
    fn an_image_whose_partner_cannot_come_any_more_is_unpaired() {
        // Left 20 has no right: right 30 tells; right 40 has no left: left 50 tells.
        assert_eq!(
            run(
                0,
                4,
                &[
                    (L, 10),
                    (R, 10),
                    (L, 20),
                    (R, 30),
                    (L, 30),
                    (R, 40),
                    (L, 50)
                ]
            ),
            [
                ("pair", 10, 10),
                ("left", 20, 0),
                ("pair", 30, 30),
                ("right", 40, 0)
            ]
        );
    }

    #[test]
    fn within_the_tolerance_the_nearest_pairs() {
        // Right 13 is within 5 of left 10 but left 14 is nearer: left 10 goes unpaired.
        assert_eq!(
            run(5, 4, &[(L, 10), (L, 14), (R, 13)]),
            [("left", 10, 0), ("pair", 14, 13)]
        );
        assert_eq!(run(5, 4, &[(L, 10), (R, 16)]), [("left", 10, 0)]);
        assert_eq!(run(5, 4, &[(R, 10), (L, 14)]), [("pair", 14, 10)]);
    }

    #[test]
    fn a_side_without_partners_is_unpaired_beyond_its_capacity() {
        assert_eq!(
            run(0, 2, &[(L, 1), (L, 2), (L, 3), (L, 4)]),
            [("left", 1, 0), ("left", 2, 0)]
        );
    }

    #[test]
    fn an_image_out_of_order_takes_its_place() {
        assert_eq!(
            run(0, 4, &[(L, 20), (L, 10), (R, 10), (R, 20)]),
            [("pair", 10, 10), ("pair", 20, 20)]
        );
    }
}
