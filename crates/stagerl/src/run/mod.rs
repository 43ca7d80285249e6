//! A run on disk: its directory and every path in it ([`dir`]), the advisory lock that keeps two
//! processes from writing one run ([`lock`]), where results come from ([`provenance`]) and the
//! portable description of a checkpoint's policy ([`policy`]).

pub mod dir;
pub mod lock;
pub mod policy;
pub mod provenance;
