//! The CSV files of runs and reports, in one pattern: a row type implements [`CsvRow`] (its
//! header and how it writes one line) and, when the file is read back, [`CsvRecord`] (how it
//! parses one); [`to_csv`], [`write_csv`], [`read_csv`] and [`CsvWriter`] do the rest.
//!
//! Floats print with Rust's `{}` (the shortest text that parses back to the same value), so equal
//! values give equal bytes and a file read back gives the values written. Fields hold no commas
//! (text fields of reports are quoted by their writer).
//!
//! This file holds the rows of a run's `episodes.csv` ([`EpisodeRecord`]), `eval.csv`
//! ([`EvalPoint`]) and per-trial evaluation CSVs ([`TrialRecord`]), each with its reader and
//! writer; the report's rows live beside the report's tables.

use std::fmt::Write as _;
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

use crate::{Error, Result};

/// A row of a CSV file that is written.
pub trait CsvRow {
    /// The header line (no newline).
    const HEADER: &'static str;
    /// Append this row's fields, comma-separated, without the newline.
    fn write_row(&self, out: &mut String);
}

/// A row of a CSV file that is also read back.
pub trait CsvRecord: CsvRow + Sized {
    /// Headers of files written before a column was added, still read (their rows lack the
    /// newer columns, which parse as unknown).
    const OLDER_HEADERS: &'static [&'static str] = &[];
    /// Headers of files of this version with optional columns (written only when their
    /// setting is on).
    const OPTIONAL_HEADERS: &'static [&'static str] = &[];
    /// `header` is one of this row type's files'.
    fn known_header(header: &str) -> bool {
        header == Self::HEADER
            || Self::OLDER_HEADERS.contains(&header)
            || Self::OPTIONAL_HEADERS.contains(&header)
    }
    /// Parse the fields of one line (split at commas); `None` when malformed.
    fn parse_row(fields: &[&str]) -> Option<Self>;
}

/// Append `row` and a newline to `out`.
pub fn push_row<R: CsvRow>(out: &mut String, row: &R) {
    row.write_row(out);
    out.push('\n');
}

/// The header and every row, one per line.
pub fn to_csv<'a, R: CsvRow + 'a>(rows: impl IntoIterator<Item = &'a R>) -> String {
    to_csv_with_header(R::HEADER, rows)
}

/// [`to_csv`] under another header (a file with optional columns).
pub fn to_csv_with_header<'a, R: CsvRow + 'a>(header: &str, rows: impl IntoIterator<Item = &'a R>) -> String {
    let mut s = format!("{header}\n");
    for r in rows {
        push_row(&mut s, r);
    }
    s
}

/// Write the header and `rows` to `path` atomically.
pub fn write_csv<R: CsvRow>(path: &Path, rows: &[R]) -> Result<()> {
    crate::io::write_atomic(path, to_csv(rows).as_bytes())
}

/// Parse one line of an `R` file.
pub fn parse_line<R: CsvRecord>(line: &str, origin: &Path) -> Result<R> {
    let fields: Vec<&str> = line.trim_end().split(',').collect();
    R::parse_row(&fields)
        .ok_or_else(|| Error::InvalidInput(format!("{}: malformed row {line:?}", origin.display())))
}

/// Parse the text of an `R` file (header first; blank lines are skipped); `origin` names it in
/// errors.
pub fn parse_csv<R: CsvRecord>(text: &str, origin: &Path) -> Result<Vec<R>> {
    let mut lines = text.lines();
    let header = lines.next().map(str::trim_end);
    if !header.is_some_and(R::known_header) {
        return Err(Error::InvalidInput(format!(
            "{}: expected the header {:?}",
            origin.display(),
            R::HEADER
        )));
    }
    lines.filter(|l| !l.trim().is_empty()).map(|l| parse_line(l, origin)).collect()
}

/// Read every row of an `R` file.
pub fn read_csv<R: CsvRecord>(path: &Path) -> Result<Vec<R>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_csv(&text, path)
}

/// A float field.
pub fn num(s: &str) -> Option<f64> {
    s.parse().ok()
}

/// A `0`/`1` field.
pub fn parse_bool(s: &str) -> Option<bool> {
    match s {
        "1" => Some(true),
        "0" => Some(false),
        _ => None,
    }
}

/// An optional value (a float, a count): empty for `None`; `None` when malformed.
pub fn parse_opt<T: std::str::FromStr>(s: &str) -> Option<Option<T>> {
    if s.is_empty() {
        Some(None)
    } else {
        s.parse().ok().map(Some)
    }
}

/// Writes an optional value: nothing for `None`.
pub struct Opt<T>(pub Option<T>);

impl<T: std::fmt::Display> std::fmt::Display for Opt<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.0 {
            Some(v) => write!(f, "{v}"),
            None => Ok(()),
        }
    }
}

/// Appends rows to a CSV file, flushing each one (a run's `episodes.csv`).
pub struct CsvWriter<R> {
    out: BufWriter<File>,
    path: PathBuf,
    line: String,
    _row: PhantomData<fn(&R)>,
}

impl<R: CsvRow> CsvWriter<R> {
    fn open(file: File, path: &Path) -> CsvWriter<R> {
        CsvWriter {
            out: BufWriter::new(file),
            path: path.to_path_buf(),
            line: String::new(),
            _row: PhantomData,
        }
    }

    /// Create `path` with its header (replacing any file there).
    pub fn create(path: &Path) -> Result<CsvWriter<R>> {
        Self::create_with_header(path, R::HEADER)
    }

    /// [`CsvWriter::create`] with another header (a file with optional columns).
    pub fn create_with_header(path: &Path, header: &str) -> Result<CsvWriter<R>> {
        let file = File::create(path).map_err(|e| Error::io(path, e))?;
        let mut csv = CsvWriter::open(file, path);
        writeln!(csv.out, "{header}").and_then(|_| csv.out.flush()).map_err(|e| Error::io(path, e))?;
        Ok(csv)
    }

    /// Open an existing file for appending.
    pub fn append(path: &Path) -> Result<CsvWriter<R>> {
        let file = OpenOptions::new().append(true).open(path).map_err(|e| Error::io(path, e))?;
        Ok(CsvWriter::open(file, path))
    }

    /// Append one row and flush it.
    pub fn write(&mut self, r: &R) -> Result<()> {
        self.line.clear();
        push_row(&mut self.line, r);
        self.out
            .write_all(self.line.as_bytes())
            .and_then(|_| self.out.flush())
            .map_err(|e| Error::io(&self.path, e))
    }
}

/// One training episode (a row of `episodes.csv`).
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
    /// Steps of the episode that ended in contact (floor, self, obstacle); `None` in files
    /// written before contacts were recorded (an empty field).
    pub collision_steps: Option<u32>,
    /// With `train.curriculum`: the stage (0-based) the episode was played at; the column
    /// `curriculum_stage`, before `wall_s`, is written only then
    /// ([`EpisodeRecord::HEADER_WITH_STAGE`]).
    pub curriculum_stage: Option<u32>,
    /// Seconds since the run began (the only column that differs between identical runs, and
    /// the last; written to the millisecond).
    pub wall_s: f64,
}

impl CsvRow for EpisodeRecord {
    const HEADER: &'static str =
        "episode,reward,steps,success,final_distance_m,env_steps,collision_steps,wall_s";

    fn write_row(&self, out: &mut String) {
        let EpisodeRecord {
            episode,
            reward,
            steps,
            success,
            final_distance_m: d,
            env_steps,
            collision_steps,
            curriculum_stage,
            wall_s,
        } = *self;
        let (success, collisions) = (u8::from(success), Opt(collision_steps));
        let _ = write!(out, "{episode},{reward},{steps},{success},{d},{env_steps},{collisions},");
        if let Some(stage) = curriculum_stage {
            let _ = write!(out, "{stage},");
        }
        let _ = write!(out, "{wall_s:.3}");
    }
}

impl EpisodeRecord {
    /// The header of a run with `train.curriculum`.
    pub const HEADER_WITH_STAGE: &'static str =
        "episode,reward,steps,success,final_distance_m,env_steps,collision_steps,curriculum_stage,wall_s";

    /// The header of a run's `episodes.csv`: with the stage column when it has a curriculum.
    pub fn header(curriculum: bool) -> &'static str {
        if curriculum {
            Self::HEADER_WITH_STAGE
        } else {
            <Self as CsvRow>::HEADER
        }
    }
}

impl CsvRecord for EpisodeRecord {
    const OLDER_HEADERS: &'static [&'static str] =
        &["episode,reward,steps,success,final_distance_m,env_steps,wall_s"];
    const OPTIONAL_HEADERS: &'static [&'static str] = &[EpisodeRecord::HEADER_WITH_STAGE];

    fn parse_row(f: &[&str]) -> Option<EpisodeRecord> {
        let (head, collision_steps, curriculum_stage, wall_s) = match f {
            [head @ .., c, s, w] if f.len() == 9 => (head, parse_opt(c)?, Some(s.parse().ok()?), w),
            [head @ .., c, w] if f.len() == 8 => (head, parse_opt(c)?, None, w),
            [head @ .., w] if f.len() == 7 => (head, None, None, w),
            _ => return None,
        };
        let [episode, reward, steps, success, final_distance_m, env_steps] = head else { return None };
        let (episode, steps, env_steps) =
            (episode.parse().ok()?, steps.parse().ok()?, env_steps.parse().ok()?);
        let (reward, final_distance_m, wall_s) = (num(reward)?, num(final_distance_m)?, num(wall_s)?);
        let success = parse_bool(success)?;
        Some(EpisodeRecord {
            episode,
            reward,
            steps,
            success,
            final_distance_m,
            env_steps,
            collision_steps,
            curriculum_stage,
            wall_s,
        })
    }
}

/// Appends rows to a run's `episodes.csv`.
pub type EpisodeCsv = CsvWriter<EpisodeRecord>;

/// Read every row of an `episodes.csv`.
pub fn read_episodes(path: &Path) -> Result<Vec<EpisodeRecord>> {
    read_csv(path)
}

/// One periodic evaluation of the deterministic policy (a row of a run's `eval.csv`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct EvalPoint {
    pub episode: u64,
    pub env_steps: u64,
    /// In [0, 1].
    pub success_rate: f64,
    pub mean_reward: f64,
    /// Mean steps of the successful trials; `None` when none succeeded.
    pub mean_steps: Option<f64>,
    pub median_final_distance_m: f64,
}

impl CsvRow for EvalPoint {
    const HEADER: &'static str =
        "episode,env_steps,success_rate,mean_reward,mean_steps,median_final_distance_m";

    fn write_row(&self, out: &mut String) {
        let EvalPoint {
            episode,
            env_steps,
            success_rate,
            mean_reward,
            mean_steps,
            median_final_distance_m: d,
        } = *self;
        let mean_steps = Opt(mean_steps);
        let _ = write!(out, "{episode},{env_steps},{success_rate},{mean_reward},{mean_steps},{d}");
    }
}

impl CsvRecord for EvalPoint {
    fn parse_row(f: &[&str]) -> Option<EvalPoint> {
        let [episode, env_steps, success_rate, mean_reward, mean_steps, median] = f else { return None };
        let (episode, env_steps) = (episode.parse().ok()?, env_steps.parse().ok()?);
        let (success_rate, mean_reward, mean_steps) =
            (num(success_rate)?, num(mean_reward)?, parse_opt(mean_steps)?);
        let median_final_distance_m = num(median)?;
        Some(EvalPoint { episode, env_steps, success_rate, mean_reward, mean_steps, median_final_distance_m })
    }
}

/// Read a run's `eval.csv`.
pub fn read_eval_points(path: &Path) -> Result<Vec<EvalPoint>> {
    read_csv(path)
}

/// One evaluation episode (a row of a per-trial evaluation CSV, `eval-seed<N>.csv`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrialRecord {
    pub trial: u32,
    /// Eq. 16 episode reward (bonus included).
    pub reward: f64,
    pub steps: u32,
    pub success: bool,
    /// D_PT at the start, metres.
    pub start_distance_m: f64,
    /// D_PT at the end, metres.
    pub final_distance_m: f64,
    /// The target, metres.
    pub target: [f64; 3],
    /// Steps of the trial that ended in contact; `None` in files written before contacts were
    /// recorded.
    pub collision_steps: Option<u32>,
}

impl CsvRow for TrialRecord {
    const HEADER: &'static str = "trial,reward,steps,success,start_distance_m,final_distance_m,\
                                  target_x_m,target_y_m,target_z_m,collision_steps";

    fn write_row(&self, out: &mut String) {
        let TrialRecord {
            trial,
            reward,
            steps,
            success,
            start_distance_m: d0,
            final_distance_m: d,
            target,
            collision_steps,
        } = *self;
        let ([x, y, z], success, c) = (target, u8::from(success), Opt(collision_steps));
        let _ = write!(out, "{trial},{reward},{steps},{success},{d0},{d},{x},{y},{z},{c}");
    }
}

impl CsvRecord for TrialRecord {
    const OLDER_HEADERS: &'static [&'static str] =
        &["trial,reward,steps,success,start_distance_m,final_distance_m,target_x_m,target_y_m,target_z_m"];

    fn parse_row(f: &[&str]) -> Option<TrialRecord> {
        let (f, collision_steps) = match f {
            [head @ .., c] if f.len() == 10 => (head, parse_opt(c)?),
            _ => (f, None),
        };
        let [trial, reward, steps, success, start, fin, x, y, z] = f else { return None };
        let (trial, steps, success) = (trial.parse().ok()?, steps.parse().ok()?, parse_bool(success)?);
        let (reward, start_distance_m, final_distance_m) = (num(reward)?, num(start)?, num(fin)?);
        let target = [num(x)?, num(y)?, num(z)?];
        Some(TrialRecord {
            trial,
            reward,
            steps,
            success,
            start_distance_m,
            final_distance_m,
            target,
            collision_steps,
        })
    }
}

/// Write a per-trial evaluation CSV (atomically).
pub fn write_trials_csv(path: &Path, records: &[TrialRecord]) -> Result<()> {
    write_csv(path, records)
}

/// Read a per-trial evaluation CSV (written by [`write_trials_csv`]).
pub fn read_trials_csv(path: &Path) -> Result<Vec<TrialRecord>> {
    read_csv(path)
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
                collision_steps: Some(3),
                curriculum_stage: None,
            },
            EpisodeRecord {
                episode: 2,
                reward: 19.4,
                steps: 6,
                success: true,
                final_distance_m: 0.0099,
                env_steps: 56,
                wall_s: 0.02,
                collision_steps: Some(0),
                curriculum_stage: None,
            },
        ];
        let mut w = EpisodeCsv::create(&p).unwrap();
        w.write(&rows[0]).unwrap();
        drop(w);
        let mut w = EpisodeCsv::append(&p).unwrap();
        w.write(&rows[1]).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert_eq!(
            text,
            "episode,reward,steps,success,final_distance_m,env_steps,collision_steps,wall_s\n\
             1,-12.345678901234,50,0,0.1234,50,3,0.012\n2,19.4,6,1,0.0099,56,0,0.020\n"
        );
        let back = read_episodes(&p).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[0].reward, rows[0].reward);
        assert_eq!(back[1], EpisodeRecord { wall_s: 0.02, ..rows[1] });
        assert!(parse_line::<EpisodeRecord>("1,2,3", &p).is_err());
        assert!(parse_line::<EpisodeRecord>("1,2,3,1,0.1,3,0.5,x", &p).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The curriculum's stage column: written (before `wall_s`) only for rows that have a stage,
    /// under its own header, and read back.
    #[test]
    fn the_curriculum_stage_column_is_written_only_when_set() {
        let row = EpisodeRecord {
            episode: 3,
            reward: 1.5,
            steps: 7,
            success: true,
            final_distance_m: 0.005,
            env_steps: 99,
            collision_steps: Some(0),
            curriculum_stage: Some(2),
            wall_s: 0.5,
        };
        let text = to_csv_with_header(EpisodeRecord::header(true), [&row]);
        assert_eq!(
            text,
            "episode,reward,steps,success,final_distance_m,env_steps,collision_steps,curriculum_stage,wall_s\n\
             3,1.5,7,1,0.005,99,0,2,0.500\n"
        );
        assert_eq!(parse_csv::<EpisodeRecord>(&text, Path::new("episodes.csv")).unwrap(), vec![row]);
        let plain = EpisodeRecord { curriculum_stage: None, ..row };
        let text = to_csv([&plain]);
        assert_eq!(EpisodeRecord::header(false), EpisodeRecord::HEADER);
        assert_eq!(text.lines().nth(1), Some("3,1.5,7,1,0.005,99,0,0.500"));
        assert_eq!(parse_csv::<EpisodeRecord>(&text, Path::new("episodes.csv")).unwrap(), vec![plain]);
    }

    /// Files written before contacts were recorded read back, the new columns unknown.
    #[test]
    fn older_files_without_collision_columns_still_read() {
        let old =
            "episode,reward,steps,success,final_distance_m,env_steps,wall_s\n1,-3.5,50,0,0.25,50,0.010\n";
        let rows = parse_csv::<EpisodeRecord>(old, Path::new("episodes.csv")).unwrap();
        assert_eq!((rows[0].steps, rows[0].collision_steps, rows[0].final_distance_m), (50, None, 0.25));
        // Written again, the unknown count is an empty field under the current header.
        assert!(to_csv(&rows).ends_with("1,-3.5,50,0,0.25,50,,0.010\n"), "{}", to_csv(&rows));
        let old_trials =
            "trial,reward,steps,success,start_distance_m,final_distance_m,target_x_m,target_y_m,\
                          target_z_m\n7,19.5,6,1,0.4,0.008,0.1,0.2,0.3\n";
        let t = parse_csv::<TrialRecord>(old_trials, Path::new("eval.csv")).unwrap();
        assert_eq!((t[0].trial, t[0].success, t[0].collision_steps), (7, true, None));
        let new = TrialRecord { collision_steps: Some(2), ..t[0] };
        assert_eq!(parse_csv::<TrialRecord>(&to_csv(&[new]), Path::new("e.csv")).unwrap(), vec![new]);
        assert!(to_csv(&[new]).ends_with(",0.3,2\n"));
    }

    #[test]
    fn eval_points_round_trip_with_and_without_mean_steps() {
        let rows = [rows_0(), EvalPoint { mean_steps: Some(7.5), episode: 500, ..rows_0() }];
        let text = to_csv(&rows);
        assert_eq!(
            text,
            "episode,env_steps,success_rate,mean_reward,mean_steps,median_final_distance_m\n\
             250,12000,0.5,-3.25,,0.1\n500,12000,0.5,-3.25,7.5,0.1\n"
        );
        assert_eq!(parse_csv::<EvalPoint>(&text, Path::new("eval.csv")).unwrap(), rows);
        let e = parse_csv::<EvalPoint>("episode\n", Path::new("eval.csv")).unwrap_err().to_string();
        assert!(e.contains("eval.csv") && e.contains("header"), "{e}");
    }

    fn rows_0() -> EvalPoint {
        EvalPoint {
            episode: 250,
            env_steps: 12000,
            success_rate: 0.5,
            mean_reward: -3.25,
            mean_steps: None,
            median_final_distance_m: 0.1,
        }
    }
}
