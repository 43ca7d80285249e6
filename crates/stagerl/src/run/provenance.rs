//! Where results come from: `provenance.json` in a results directory (a sweep, a report) records
//! the stagerl version, the git commit it was built from and whether the tree had uncommitted
//! changes, the machine, and every command that wrote into the directory with its start and end
//! times (UTC), wall time and CPU time. A sweep resumed over several sessions lists each session;
//! the totals add them up.

use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use crate::{Error, Result};

/// The file name in a results directory.
pub const FILE: &str = "provenance.json";

/// The code a binary was built from.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Code {
    pub stagerl_version: String,
    /// `None` when not built from a git checkout.
    pub git_commit: Option<String>,
    /// Tracked files had uncommitted changes at build time.
    pub git_dirty: Option<bool>,
}

/// `(commit, dirty)` from a build script's strings: empty or unknown values are `None`.
fn build_facts(commit: &str, dirty: &str) -> (Option<String>, Option<bool>) {
    let commit = (!commit.is_empty()).then(|| commit.to_string());
    let dirty = match dirty {
        "true" => Some(true),
        "false" => Some(false),
        _ => None,
    };
    (commit, dirty)
}

/// The build facts the program recorded at start ([`Code::record_build`]).
static BUILD: std::sync::OnceLock<(Option<String>, Option<bool>)> = std::sync::OnceLock::new();

impl Code {
    /// Record the git commit the program was built from and whether its tree had uncommitted
    /// changes (`"true"`, `"false"`, or empty when unknown), as the program's build script found
    /// them. The `stagerl` binary does it first thing; a program that does not leaves the commit
    /// unknown (`None`) in what it writes. The first call wins.
    pub fn record_build(commit: &str, dirty: &str) {
        let _ = BUILD.set(build_facts(commit, dirty));
    }

    /// This program's code version: the library's version and the recorded build facts.
    pub fn current() -> Code {
        let (git_commit, git_dirty) = BUILD.get().cloned().unwrap_or((None, None));
        Code { stagerl_version: env!("CARGO_PKG_VERSION").to_string(), git_commit, git_dirty }
    }

    /// `0.1.0 (abc1234)`, with `+dirty` when the tree had changes.
    pub fn describe(&self) -> String {
        match (&self.git_commit, self.git_dirty) {
            (Some(c), d) => {
                format!(
                    "{} ({}{})",
                    self.stagerl_version,
                    &c[..c.len().min(12)],
                    if d == Some(true) { "+dirty" } else { "" }
                )
            }
            (None, _) => format!("{} (no git commit)", self.stagerl_version),
        }
    }
}

/// The machine a session ran on.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Machine {
    pub cpu_model: String,
    /// Logical CPUs available to the process.
    pub cores: usize,
    pub os: String,
    pub arch: String,
}

impl Machine {
    pub fn current() -> Machine {
        let cpu_model = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split(':').nth(1))
                    .map(|m| m.trim().to_string())
            })
            .unwrap_or_else(|| "unknown".to_string());
        Machine {
            cpu_model,
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            os: std::env::consts::OS.to_string(),
            arch: std::env::consts::ARCH.to_string(),
        }
    }
}

/// One command that wrote into the directory.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Session {
    /// The command line, program name first.
    pub command: Vec<String>,
    pub code: Code,
    pub machine: Machine,
    /// UTC, RFC 3339.
    pub start: String,
    pub end: Option<String>,
    pub wall_s: f64,
    /// User + system CPU time of the process and its finished children, seconds.
    pub cpu_s: f64,
    /// How it ended: `finished`, `interrupted`, or the error.
    pub outcome: String,
}

/// The whole file.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    pub sessions: Vec<Session>,
    pub total_wall_s: f64,
    pub total_cpu_hours: f64,
}

impl Provenance {
    /// Read `dir/provenance.json`, or an empty record when there is none.
    pub fn load(dir: &Path) -> Result<Provenance> {
        let path = dir.join(FILE);
        match std::fs::read_to_string(&path) {
            Ok(text) => serde_json::from_str(&text).map_err(|e| {
                Error::InvalidInput(format!("{}: not a provenance record: {e}", path.display()))
            }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Provenance::default()),
            Err(e) => Err(Error::io(&path, e)),
        }
    }

    /// Write it to `dir/provenance.json` atomically, totals recomputed.
    pub fn save(&mut self, dir: &Path) -> Result<()> {
        self.total_wall_s = self.sessions.iter().map(|s| s.wall_s).sum();
        self.total_cpu_hours = self.sessions.iter().map(|s| s.cpu_s).sum::<f64>() / 3600.0;
        let json = serde_json::to_string_pretty(self)
            .map_err(|e| Error::InvalidInput(format!("provenance: {e}")))?;
        crate::io::write_atomic(&dir.join(FILE), json.as_bytes())
    }

    /// Every distinct code version among the sessions.
    pub fn code_versions(&self) -> Vec<&Code> {
        let mut v: Vec<&Code> = Vec::new();
        for s in &self.sessions {
            if !v.contains(&&s.code) {
                v.push(&s.code);
            }
        }
        v
    }
}

/// The provenance of a report written from `input` (a sweep directory) into `out`: the sweep's
/// sessions (its `provenance.json`, when it has one), then the report's own session for
/// `command`, started at `started` (`Recorder::clock`), saved as `out/provenance.json`.
pub fn record_report(input: &Path, out: &Path, command: Vec<String>, started: Clock) -> Result<Provenance> {
    let mut p = Provenance::load(input)?;
    p.sessions.push(Session {
        command,
        code: Code::current(),
        machine: Machine::current(),
        start: started.start,
        end: Some(rfc3339(SystemTime::now())),
        wall_s: started.instant.elapsed().as_secs_f64(),
        cpu_s: cpu_seconds() - started.cpu0,
        outcome: "finished".into(),
    });
    p.save(out)?;
    Ok(p)
}

/// When something started: wall clock (UTC), monotonic clock and CPU time.
#[derive(Clone, Debug)]
pub struct Clock {
    start: String,
    instant: Instant,
    cpu0: f64,
}

impl Clock {
    pub fn now() -> Clock {
        Clock { start: rfc3339(SystemTime::now()), instant: Instant::now(), cpu0: cpu_seconds() }
    }
}

impl Provenance {
    /// A Markdown section: code versions (a warning when results come from several), machines,
    /// commands, wall time and CPU hours.
    pub fn render_markdown(&self) -> String {
        let mut s = String::from("\n## Provenance\n\n");
        let versions = self.code_versions();
        let list: Vec<String> = versions.iter().map(|c| format!("`{}`", c.describe())).collect();
        s.push_str(&format!("Code: {}.", list.join(", ")));
        if versions.len() > 1 {
            s.push_str(" **These results come from more than one code version.**");
        }
        if versions.iter().any(|c| c.git_dirty == Some(true)) {
            s.push_str(" Some were built from a tree with uncommitted changes (`+dirty`).");
        }
        let mut machines: Vec<String> = self
            .sessions
            .iter()
            .map(|x| format!("{} ({} cores)", x.machine.cpu_model, x.machine.cores))
            .collect();
        machines.sort();
        machines.dedup();
        s.push_str(&format!(
            "\nMachine(s): {}. Wall time {:.0} s, CPU time {:.2} h over {} command(s):\n\n",
            machines.join("; "),
            self.total_wall_s,
            self.total_cpu_hours,
            self.sessions.len()
        ));
        for x in &self.sessions {
            s.push_str(&format!(
                "- `{}`: {} to {}, {:.0} s, {:.2} CPU h, {}\n",
                x.command.join(" "),
                x.start,
                x.end.as_deref().unwrap_or("(did not finish)"),
                x.wall_s,
                x.cpu_s / 3600.0,
                x.outcome
            ));
        }
        s
    }
}

/// A session being recorded: [`Recorder::start`] appends it (so an interrupted session still
/// shows), [`Recorder::finish`] fills in its end.
pub struct Recorder {
    index: usize,
    started: Instant,
    cpu0: f64,
}

impl Recorder {
    /// Append a session for `command` to `dir`'s record (under the directory's sweep lock: several
    /// processes may share a sweep).
    pub fn start(dir: &Path, command: Vec<String>) -> Result<Recorder> {
        let _lock = crate::run::lock::DirLock::sweep(dir)?;
        let mut p = Provenance::load(dir)?;
        p.sessions.push(Session {
            command,
            code: Code::current(),
            machine: Machine::current(),
            start: rfc3339(SystemTime::now()),
            end: None,
            wall_s: 0.0,
            cpu_s: 0.0,
            outcome: "running (or killed)".into(),
        });
        p.save(dir)?;
        Ok(Recorder { index: p.sessions.len() - 1, started: Instant::now(), cpu0: cpu_seconds() })
    }

    /// Record the session's end and how it ended.
    pub fn finish(self, dir: &Path, outcome: &str) -> Result<()> {
        let _lock = crate::run::lock::DirLock::sweep(dir)?;
        let mut p = Provenance::load(dir)?;
        if let Some(s) = p.sessions.get_mut(self.index) {
            s.end = Some(rfc3339(SystemTime::now()));
            s.wall_s = self.started.elapsed().as_secs_f64();
            s.cpu_s = cpu_seconds() - self.cpu0;
            s.outcome = outcome.to_string();
        }
        p.save(dir)
    }
}

/// User + system CPU seconds of this process and its waited-for children (`/proc/self/stat`, in
/// the kernel's clock ticks, `sysconf(_SC_CLK_TCK)` per second); 0 where unavailable.
pub fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // Fields after the command name (which may hold spaces) start at ") ".
    let Some(rest) = stat.rsplit_once(") ").map(|(_, r)| r) else { return 0.0 };
    let f: Vec<&str> = rest.split_whitespace().collect();
    // utime, stime, cutime, cstime are fields 14-17 of the line: 11-14 after the name.
    let ticks: f64 = (11..15).filter_map(|i| f.get(i).and_then(|v| v.parse::<f64>().ok())).sum();
    // SAFETY: sysconf only reads a system constant.
    let per_s = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if per_s > 0 {
        ticks / per_s as f64
    } else {
        0.0
    }
}

/// `t` as `YYYY-MM-DDTHH:MM:SSZ` (UTC).
pub fn rfc3339(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days as i64);
    format!("{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem % 3600 / 60, rem % 60)
}

/// Days since 1970-01-01 to (year, month, day) in the proleptic Gregorian calendar
/// (H. Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn dates_are_utc_rfc3339() {
        assert_eq!(rfc3339(UNIX_EPOCH), "1970-01-01T00:00:00Z");
        assert_eq!(rfc3339(UNIX_EPOCH + Duration::from_secs(951_782_400)), "2000-02-29T00:00:00Z");
        assert_eq!(rfc3339(UNIX_EPOCH + Duration::from_secs(1_796_000_000)), "2026-11-30T00:53:20Z");
    }

    #[test]
    fn sessions_accumulate_and_totals_add_up() {
        let dir = std::env::temp_dir().join(format!("stagerl-prov-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let r = Recorder::start(&dir, vec!["stagerl".into(), "reproduce".into()]).unwrap();
        let p = Provenance::load(&dir).unwrap();
        assert_eq!(p.sessions.len(), 1);
        assert_eq!(p.sessions[0].end, None);
        let spin = Instant::now();
        while spin.elapsed() < Duration::from_millis(30) {}
        r.finish(&dir, "finished").unwrap();
        Recorder::start(&dir, vec!["stagerl".into()]).unwrap().finish(&dir, "interrupted").unwrap();
        let p = Provenance::load(&dir).unwrap();
        assert_eq!(p.sessions.len(), 2);
        assert!(p.sessions[0].wall_s >= 0.03 && p.sessions[0].end.is_some());
        assert_eq!(p.sessions[1].outcome, "interrupted");
        assert!((p.total_wall_s - p.sessions.iter().map(|s| s.wall_s).sum::<f64>()).abs() < 1e-12);
        assert_eq!(p.code_versions().len(), 1);
        assert_eq!(p.sessions[0].code, Code::current());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn build_facts_give_the_code_version() {
        let commit = "0123456789abcdef0123456789abcdef01234567";
        let (git_commit, git_dirty) = build_facts(commit, "true");
        let c = Code { stagerl_version: "0.1.0".into(), git_commit, git_dirty };
        assert_eq!((c.git_commit.as_deref(), c.git_dirty), (Some(commit), Some(true)));
        assert_eq!(c.describe(), "0.1.0 (0123456789ab+dirty)");
        assert_eq!(build_facts(commit, "false").1, Some(false));
        // Not built from a git checkout: nothing is claimed.
        let (git_commit, git_dirty) = build_facts("", "");
        let none = Code { stagerl_version: "0.1.0".into(), git_commit, git_dirty };
        assert_eq!(none.describe(), "0.1.0 (no git commit)");
        assert_eq!(none.git_dirty, None);
    }
}
