//! `episodes.csv`: one row per training episode.

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::{Error, Result};

/// One training episode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EpisodeRecord {
    /// 1-based episode number.
    pub episode: u64,
    /// R_episode of eq. 16: the sum of the step rewards (bonus included) up to the episode's end.
    pub reward: f64,
    /// Steps taken.
    pub steps: u32,
    /// The target was reached.
    pub success: bool,
    /// D_PT at the episode's end, metres.
    pub final_distance_m: f64,
    /// Environment steps since the run began.
    pub env_steps: u64,
    /// Seconds since the run began (the only column that differs between identical runs).
    pub wall_s: f64,
}

impl EpisodeRecord {
    /// The CSV header.
    pub const HEADER: &'static str = "episode,reward,steps,success,final_distance_m,env_steps,wall_s";

    /// One CSV line (no newline). Floats print in Rust's shortest round-trip form, so equal values
    /// give equal text.
    pub fn to_csv(&self) -> String {
        format!(
            "{},{},{},{},{},{},{:.3}",
            self.episode,
            self.reward,
            self.steps,
            u8::from(self.success),
            self.final_distance_m,
            self.env_steps,
            self.wall_s
        )
    }

    /// Parse a line written by [`EpisodeRecord::to_csv`].
    pub fn from_csv(line: &str) -> Result<EpisodeRecord> {
        let bad = || Error::InvalidInput(format!("episodes.csv: malformed row {line:?}"));
        let f: Vec<&str> = line.trim_end().split(',').collect();
        if f.len() != 7 {
            return Err(bad());
        }
        Ok(EpisodeRecord {
            episode: f[0].parse().map_err(|_| bad())?,
            reward: f[1].parse().map_err(|_| bad())?,
            steps: f[2].parse().map_err(|_| bad())?,
            success: match f[3] {
                "1" => true,
                "0" => false,
                _ => return Err(bad()),
            },
            final_distance_m: f[4].parse().map_err(|_| bad())?,
            env_steps: f[5].parse().map_err(|_| bad())?,
            wall_s: f[6].parse().map_err(|_| bad())?,
        })
    }
}

/// Appends episode rows, flushing each one.
pub struct EpisodeCsv {
    out: BufWriter<File>,
    path: PathBuf,
}

impl EpisodeCsv {
    /// Create `path` with its header (replacing any file there).
    pub fn create(path: &Path) -> Result<EpisodeCsv> {
        let file = File::create(path).map_err(|e| Error::io(path, e))?;
        let mut csv = EpisodeCsv { out: BufWriter::new(file), path: path.to_path_buf() };
        writeln!(csv.out, "{}", EpisodeRecord::HEADER).map_err(|e| Error::io(path, e))?;
        csv.out.flush().map_err(|e| Error::io(path, e))?;
        Ok(csv)
    }

    /// Open an existing file for appending.
    pub fn append(path: &Path) -> Result<EpisodeCsv> {
        let file = OpenOptions::new().append(true).open(path).map_err(|e| Error::io(path, e))?;
        Ok(EpisodeCsv { out: BufWriter::new(file), path: path.to_path_buf() })
    }

    /// Append one row and flush it.
    pub fn write(&mut self, r: &EpisodeRecord) -> Result<()> {
        writeln!(self.out, "{}", r.to_csv())
            .and_then(|_| self.out.flush())
            .map_err(|e| Error::io(&self.path, e))
    }
}

/// Read every row of an `episodes.csv`.
pub fn read_episodes(path: &Path) -> Result<Vec<EpisodeRecord>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut lines = text.lines();
    match lines.next() {
        Some(h) if h.trim_end() == EpisodeRecord::HEADER => {}
        _ => {
            return Err(Error::InvalidInput(format!(
                "{}: expected the header {:?}",
                path.display(),
                EpisodeRecord::HEADER
            )))
        }
    }
    lines.filter(|l| !l.trim().is_empty()).map(EpisodeRecord::from_csv).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_round_trip() {
        let dir = std::env::temp_dir().join(format!("stagerl-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("episodes.csv");
        let rows = [
            EpisodeRecord {
                episode: 1,
                reward: -12.345678901234,
                steps: 50,
                success: false,
                final_distance_m: 0.1234,
                env_steps: 50,
                wall_s: 0.0123,
            },
            EpisodeRecord {
                episode: 2,
                reward: 19.4,
                steps: 6,
                success: true,
                final_distance_m: 0.0099,
                env_steps: 56,
                wall_s: 0.02,
            },
        ];
        let mut w = EpisodeCsv::create(&p).unwrap();
        w.write(&rows[0]).unwrap();
        drop(w);
        let mut w = EpisodeCsv::append(&p).unwrap();
        w.write(&rows[1]).unwrap();
        let back = read_episodes(&p).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[0].reward, rows[0].reward);
        assert_eq!(back[1], EpisodeRecord { wall_s: 0.02, ..rows[1] });
        assert!(EpisodeRecord::from_csv("1,2,3").is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
