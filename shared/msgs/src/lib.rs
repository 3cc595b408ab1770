//! The messages the pipeline's stages exchange, and the names of the services that carry
//! them.
//!
//! Every message is a slice of fixed-layout records (`#[repr(C)]`, no pointers) under a
//! user header, so a subscriber in another process reads it in place from shared memory.
//! A frame's messages are headed by its [`FrameHeader`] (what every frame has) and the
//! results of the stages upstream, each in its own record: images by a [`FrameHeader`],
//! segments by a [`SegmentsHeader`] (with the [`Detection`]), tracks and poses by a
//! [`TracksHeader`] (with the [`Detection`] and the [`Matching`]); status reports and
//! commands have no header. The topology is declared once, in [`PIPELINE`]:
//! [`Topic::consumers`] (which stages read a topic, and so which stages a publisher wakes)
//! and the named [`StampSlot`]s of a frame are derived from it.
//!
//! Codes (a stage, a status, a mode) travel as [`Code`]s: a `u32` that another, possibly
//! older or crashed, process wrote, read back only through a checked conversion, so no
//! value in shared memory is ever taken for an enum it is not.
//!
//! The records the ground-station link forwards (headers, segments, tracks, poses, status
//! reports) are also serde types.

use iceoryx2::prelude::ZeroCopySend;
use std::fmt;
use std::marker::PhantomData;

/// An enum that travels as a `u32` code ([`Code`]).
pub trait WireEnum: Copy + fmt::Debug + Into<u32> + TryFrom<u32> + 'static {
    /// What the code names, for errors ("frame status").
    const WHAT: &'static str;
}

/// A code read from the wire that names no variant: written by another build, or garbage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} code {code}")]
pub struct UnknownCode {
    /// What the code should have named ([`WireEnum::WHAT`]).
    pub what: &'static str,
    /// The code.
    pub code: u32,
}

/// An `E` on the wire: its `u32` code. Whatever another process wrote, reading a `Code` is
/// sound (any `u32` is a valid `Code`, where a `#[repr(u32)]` enum read from shared memory
/// with an unknown discriminant would be undefined behaviour); the only way to the enum is
/// the checked [`Code::get`], and the only way in is an `E`.
#[repr(transparent)]
pub struct Code<E> {
    raw: u32,
    kind: PhantomData<E>,
}

impl<E: WireEnum> Code<E> {
    /// The code of `value`.
    pub fn new(value: E) -> Self {
        Self {
            raw: value.into(),
            kind: PhantomData,
        }
    }

    /// The value, or an error naming the code when it names no `E`.
    pub fn get(self) -> Result<E, UnknownCode> {
        E::try_from(self.raw).map_err(|_| UnknownCode {
            what: E::WHAT,
            code: self.raw,
        })
    }

    /// Whether this is the code of `value`.
    pub fn is(self, value: E) -> bool {
        self.raw == value.into()
    }

    /// The bare code, for records and messages that show it as it was read.
    pub fn raw(self) -> u32 {
        self.raw
    }
}

impl<E: WireEnum> From<E> for Code<E> {
    fn from(value: E) -> Self {
        Self::new(value)
    }
}

impl<E> Clone for Code<E> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<E> Copy for Code<E> {}

impl<E> PartialEq for Code<E> {
    fn eq(&self, other: &Self) -> bool {
        self.raw == other.raw
    }
}

impl<E> Eq for Code<E> {}

impl<E: WireEnum + Default> Default for Code<E> {
    fn default() -> Self {
        Self::new(E::default())
    }
}

impl<E: WireEnum> fmt::Debug for Code<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.get() {
            Ok(value) => write!(f, "{value:?}"),
            Err(unknown) => write!(f, "<{unknown}>"),
        }
    }
}

// SAFETY: a `Code` is one `u32` (`repr(transparent)`; the `PhantomData` takes no room): no
// pointer, no handle, the same layout in every process, and every bit pattern is valid.
#[allow(unsafe_code)]
unsafe impl<E: WireEnum> ZeroCopySend for Code<E> {}

impl<E: WireEnum> serde::Serialize for Code<E> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_u32(self.raw)
    }
}

/// Decoded as it was sent, like a code read from shared memory: one that names no `E` (a
/// newer build's) is an error only when [`Code::get`] reads it, so the rest of its message
/// still arrives.
impl<'de, E: WireEnum> serde::Deserialize<'de> for Code<E> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        Ok(Self {
            raw: u32::deserialize(deserializer)?,
            kind: PhantomData,
        })
    }
}

/// Declares an enum that travels as a [`Code`]: `#[repr(u32)]` with an explicit code per
/// variant, its [`WireEnum::WHAT`], and `ALL`, every variant in the order declared (so a
/// test over `ALL` covers a variant added later).
macro_rules! wire_enum {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident: $what:literal {
            $( $(#[$variant_meta:meta])* $variant:ident = $code:literal, )+
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, TryFromPrimitive, IntoPrimitive)]
        #[repr(u32)]
        $vis enum $name {
            $( $(#[$variant_meta])* $variant = $code, )+
        }

        impl WireEnum for $name {
            const WHAT: &'static str = $what;
        }

        impl $name {
            /// Every variant, in the order declared.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];
        }
    };
}

/// A `u32` argument read from the wire as an `E` (a report's `detail`, a command's
/// `value`: arguments whose meaning depends on the message's kind), checked.
pub fn decode<E: WireEnum>(raw: u32) -> Result<E, UnknownCode> {
    E::try_from(raw).map_err(|_| UnknownCode {
        what: E::WHAT,
        code: raw,
    })
}

mod clock;
pub mod pipeline;
mod records;
mod topology;

pub use clock::now_ns;
pub use pipeline::{NodeDecl, PIPELINE, StampSlot, TopicOf, topics};
pub use records::*;
pub use topology::{StageKind, Topic, wake_service_name};

#[cfg(test)]
mod tests {
    use super::*;

    /// Every variant of `E` goes onto the wire and comes back; the codes are distinct; a
    /// code past the last one is an error naming what it should have been.
    fn round_trips<E: WireEnum + PartialEq>(all: &[E]) {
        for &value in all {
            let code = Code::new(value);
            assert_eq!(code.get(), Ok(value), "{value:?}");
            assert!(code.is(value));
            assert_eq!(decode::<E>(code.raw()), Ok(value));
        }
        let mut raws: Vec<u32> = all.iter().map(|&v| v.into()).collect();
        raws.sort_unstable();
        raws.dedup();
        assert_eq!(
            raws.len(),
            all.len(),
            "two {} variants share a code",
            E::WHAT
        );
        let unknown = raws.last().map_or(0, |&r| r + 1);
        assert!(
            E::try_from(unknown).is_err(),
            "{} has more variants",
            E::WHAT
        );
        assert_eq!(
            decode::<E>(unknown),
            Err(UnknownCode {
                what: E::WHAT,
                code: unknown
            })
        );
    }

    #[test]
    fn every_code_round_trips_and_an_unknown_one_is_refused() {
        round_trips(StageKind::ALL);
        round_trips(FrameStatus::ALL);
        round_trips(MatcherMode::ALL);
        round_trips(Detector::ALL);
        round_trips(StatusKind::ALL);
        round_trips(CameraFailure::ALL);
        round_trips(Command::ALL);
    }

    /// What another process left in shared memory: a header whose codes name nothing.
    fn garbled(frame_id: u64, status: u32, stage: u32) -> FrameHeader {
        FrameHeader {
            status: Code {
                raw: status,
                kind: PhantomData,
            },
            status_by: Code {
                raw: stage,
                kind: PhantomData,
            },
            ..FrameHeader::new(frame_id, 0, 0)
        }
    }

    #[test]
    fn an_unknown_code_read_back_is_an_error_naming_it() {
        let header = garbled(3, 77, 9);
        let err = header.status.get().err().map(|e| e.to_string());
        assert_eq!(err.as_deref(), Some("unknown frame status code 77"));
        let err = header.status_by.get().err().map(|e| e.to_string());
        assert_eq!(err.as_deref(), Some("unknown stage code 9"));
        assert!(!header.is_ok(), "an unknown status is not Ok");
        assert!(format!("{header:?}").contains("unknown frame status code 77"));
        // Known codes read back as themselves.
        let mut ok = header;
        ok.mark(FrameStatus::DroppedLate, StageKind::Matcher);
        assert_eq!(ok.status.get(), Ok(FrameStatus::DroppedLate));
        assert_eq!(ok.status_by.get(), Ok(StageKind::Matcher));
    }

    #[test]
    fn a_code_is_a_bare_u32_on_the_wire() {
        assert_eq!(std::mem::size_of::<Code<FrameStatus>>(), 4);
        assert_eq!(std::mem::align_of::<Code<Command>>(), 4);
        assert_eq!(Code::new(FrameStatus::StageError).raw(), 3);
        assert_eq!(
            Code::<StageKind>::default().get(),
            Ok(StageKind::FrameSource)
        );
    }

    #[test]
    fn stage_results_start_empty_and_carry_downstream() {
        let frame = FrameHeader::new(5, 1, 2);
        assert!(frame.is_ok());
        let mut segments = SegmentsHeader::from(frame);
        assert_eq!(segments.detection, Detection::default());
        segments.detection.left_count = 4;
        let tracks = TracksHeader::from(segments);
        assert_eq!(tracks.frame, frame);
        assert_eq!(tracks.detection.left_count, 4);
        assert_eq!(tracks.matching.previous_frame_id, NO_FRAME);
        assert_eq!(tracks.matching.lbd_probe_matches, Matching::NO_PROBE);
    }

    #[test]
    fn stage_names_come_back_to_their_stage() {
        for &stage in StageKind::ALL {
            assert_eq!(StageKind::from_name(stage.name()), Some(stage));
        }
        assert_eq!(StageKind::from_name("camera"), None);
    }

    #[test]
    fn every_consumer_is_woken_by_name_in_its_run() {
        assert_eq!(Topic::Frames.service_name("r1"), "linetrack/r1/frames");
        assert_eq!(
            wake_service_name("r1", StageKind::Matcher),
            "linetrack/r1/wake/matcher"
        );
        // Every processing stage after the source consumes something.
        for stage in &StageKind::PROCESSING[1..] {
            assert!(
                Topic::ALL.iter().any(|t| t.consumers().contains(stage)),
                "{stage} consumes nothing"
            );
        }
    }

    /// The pose estimator is woken by a frame before the detector, and the matcher after
    /// both (see [`Topic::consumers`]: the order was measured).
    #[test]
    fn a_frame_wakes_the_longest_path_first_and_the_matcher_last() {
        let order = Topic::Frames.consumers();
        let at = |stage| order.iter().position(|&s| s == stage);
        let (pose, detector, matcher) = (
            at(StageKind::PoseEstimator),
            at(StageKind::LineDetector),
            at(StageKind::Matcher),
        );
        assert!(pose.is_some() && detector.is_some() && matcher.is_some());
        assert!(pose < detector && detector < matcher, "{order:?}");
    }

    #[test]
    fn a_covariance_travels_as_its_upper_triangle() {
        let mut m = [[0.0; 6]; 6];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (i.min(j) * 6 + i.max(j)) as f64;
            }
        }
        let packed = PoseRecord::pack_covariance(&m);
        assert_eq!((packed[1], packed[6], packed[20]), (1.0, 7.0, 35.0));
        assert_eq!(PoseRecord::unpack_covariance(&packed), m);
    }

    #[test]
    fn control_addressing() {
        let c = Control::new(Command::HandOver, StageKind::LineDetector, 42, 0, 0);
        assert!(c.is_for(StageKind::LineDetector, 42));
        assert!(!c.is_for(StageKind::LineDetector, 43));
        assert!(!c.is_for(StageKind::Matcher, 42));
        let all = Control { target_pid: 0, ..c };
        assert!(all.is_for(StageKind::LineDetector, 7));
    }
}
