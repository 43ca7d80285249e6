//! What every layer above builds on: the error type, the seeded random generator, scalar math,
//! run-time SIMD dispatch, the fork-join pool one run splits its work over, text bounds for
//! messages, and the value checks every config section shares. Nothing here imports another
//! folder of the library.

pub(crate) mod error;
pub mod math;
pub mod par;
pub mod rng;
pub mod simd;
pub mod text;
pub mod validate;
