//! What a run writes as it goes: the per-episode CSV and TensorBoard event files.

pub mod csv;
pub mod tensorboard;

pub use csv::{EpisodeCsv, EpisodeRecord};
pub use tensorboard::EventWriter;
