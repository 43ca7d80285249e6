//! What a run writes as it goes: its CSV files and TensorBoard event files.

pub mod csv;
pub mod tensorboard;

pub use csv::{CsvRecord, CsvRow, EpisodeCsv, EpisodeRecord, EvalPoint, TrialRecord};
pub use tensorboard::EventWriter;
