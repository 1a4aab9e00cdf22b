//! The colon's random streams: each part draws from its own, so that turning an option on
//! moves nothing else. Listed together so that no two parts share one.

pub(super) const STREAM_NOISE: u64 = 0xC010_0001;
pub(super) const STREAM_FOLDS: u64 = 0xC010_0002;
pub(super) const STREAM_POLYPS: u64 = 0xC010_0003;
pub(super) const STREAM_POOLS: u64 = 0xC010_0004;
pub(super) const STREAM_GAS: u64 = 0xC010_0005;
// Streams of the newer options: drawn only when the option is on, so the older phantoms
// stay bit for bit what they were.
pub(super) const STREAM_FILLED: u64 = 0xC010_0006;
pub(super) const STREAM_VALVE_POOL: u64 = 0xC010_0008;
pub(super) const STREAM_STOOL: u64 = 0xC010_0009;
pub(super) const STREAM_DIVERTICULA: u64 = 0xC010_000B;
// 0xC010_0007 and 0xC010_000A: the small bowel's and the skin folds' (frame.rs).
