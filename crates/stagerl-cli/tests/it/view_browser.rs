//! `stagerl view` and `stagerl plan --view` in a real headless browser (Debian's `chromium`, or
//! the binary named by `CHROMIUM`; `scripts/test.sh` installs it when missing). A missing browser
//! is a failure, not a skip.
//!
//! The page must load with no console message at all (it writes none; an uncaught exception
//! appears as a `CONSOLE` line on chromium's log), run its script (the DOM shows the step
//! counter and one option per trajectory), and draw: the screenshot's canvas area holds the
//! arm's colours, not just the background. A page with a script error is shown to fail the same
//! checks, so they can fail. The embedded data is checked against the plans themselves.

use crate::common;

use common::{bin, scratch};
use serde_json::Value;
use stagerl::agent::Algo;
use stagerl::config::Config;
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn chromium() -> String {
    std::env::var("CHROMIUM").unwrap_or_else(|_| "chromium".into())
}

/// Headless chromium on `page` with `extra` arguments (a screenshot or a DOM dump).
fn browse(page: &Path, profile: &Path, extra: &[String]) -> Output {
    let url = format!("file://{}", page.display());
    let out = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--enable-logging=stderr",
            "--v=0",
            "--window-size=800,600",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .output();
    match out {
        Ok(o) => o,
        Err(e) => panic!(
            "cannot run the headless browser `{}` ({e}): install Debian's chromium \
             (`apt-get install -y chromium`; scripts/test.sh does) or set CHROMIUM",
            chromium()
        ),
    }
}

/// The console lines of chromium's log (the page writes none).
fn console_lines(stderr: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(stderr)
        .lines()
        .filter(|l| l.contains(":CONSOLE") || l.contains("Uncaught"))
        .map(str::to_string)
        .collect()
}

/// What the canvas area (below the control bar) of a screenshot holds.
#[derive(Debug)]
struct Canvas {
    /// Pixels off the page background.
    drawn: usize,
    /// Distinct colours.
    colours: usize,
    /// Strongly coloured pixels (the arm, the path, the target; the floor grid and the page are grey).
    saturated: usize,
}

fn canvas_pixels(png_path: &Path) -> Canvas {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(png_path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    assert!(info.width >= 400 && info.height >= 300, "{}x{}", info.width, info.height);
    let (mut drawn, mut colours, mut saturated) = (0, HashSet::new(), 0);
    for y in 60..info.height as usize - 30 {
        for x in 0..info.width as usize {
            let i = (y * info.width as usize + x) * channels;
            let px = [buf[i], buf[i + 1], buf[i + 2]];
            if px != [0xf4, 0xf5, 0xf7] {
                drawn += 1;
            }
            if px.iter().max().unwrap() - px.iter().min().unwrap() > 80 {
                saturated += 1;
            }
            colours.insert(px);
        }
    }
    Canvas { drawn, colours: colours.len(), saturated }
}

/// What the browser shows of `page`: console lines, the DOM, the canvas.
fn show(page: &Path, dir: &Path) -> (Vec<String>, String, Canvas) {
    let shot = dir.join(format!("{}.png", page.file_stem().unwrap().to_string_lossy()));
    let o = browse(page, &dir.join("profile-shot"), &[format!("--screenshot={}", shot.display())]);
    assert!(o.status.success(), "chromium failed: {}", String::from_utf8_lossy(&o.stderr));
    let mut console = console_lines(&o.stderr);
    let o = browse(page, &dir.join("profile-dom"), &["--dump-dom".into()]);
    assert!(o.status.success(), "chromium failed: {}", String::from_utf8_lossy(&o.stderr));
    console.extend(console_lines(&o.stderr));
    (console, String::from_utf8_lossy(&o.stdout).into_owned(), canvas_pixels(&shot))
}

/// The JSON a view embeds.
fn view_data(html: &str) -> Value {
    let start = html.find("type=\"application/json\">").unwrap() + "type=\"application/json\">".len();
    let end = start + html[start..].find("</script>").unwrap();
    serde_json::from_str(&html[start..end]).unwrap()
}

fn trained_run(dir: &Path) -> PathBuf {
    let run = dir.join("td3");
    let mut cfg = Config::default();
    cfg.agent.algo = Algo::Td3;
    cfg.agent.hidden = vec![16, 16];
    cfg.agent.learning_starts = 100;
    cfg.train.episodes = 30;
    cfg.train.eval_every_episodes = 0;
    stagerl::train::train(&cfg, &run, |_| {}).unwrap();
    run
}

fn ok(o: Output) -> String {
    assert!(o.status.success(), "failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout).unwrap()
}

#[test]
fn the_view_loads_runs_and_draws_in_a_headless_browser() {
    let dir = scratch("view-browser");
    let run = trained_run(&dir);
    let page = dir.join("view.html");
    let r = run.to_str().unwrap();
    ok(bin()
        .args(["view", "--run", r, "--targets", "4", "--seed", "9", "--out", page.to_str().unwrap()])
        .output()
        .unwrap());
    let html = std::fs::read_to_string(&page).unwrap();
    // Self-contained: nothing is fetched.
    for needle in ["http:", "https:", " src=", " href=", "@import", "url("] {
        assert!(!html.contains(needle), "the page refers to {needle}");
    }
    // The data: the evaluation targets of seed 9, each plan's skeleton ends at its end effector.
    let data = view_data(&html);
    let trajectories = data["trajectories"].as_array().unwrap();
    assert_eq!(trajectories.len(), 4);
    let cfg = stagerl::run::dir::RunDir::new(&run).load_config().unwrap();
    let targets = stagerl::view::eval_targets(&cfg, 4, 9).unwrap();
    for (t, want) in trajectories.iter().zip(&targets) {
        let target: Vec<f64> = t["target"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert_eq!(target, want.to_vec());
        let line = format!("{{\"target\":{}}}\n", serde_json::to_string(&target).unwrap());
        let mut child = common::spawn_piped(bin().args(["plan", "--run", r, "--targets", "-"]));
        std::io::Write::write_all(&mut child.stdin.take().unwrap(), line.as_bytes()).unwrap();
        let plan: Value = serde_json::from_str(ok(child.wait_with_output().unwrap()).trim()).unwrap();
        let frames = t["frames"].as_array().unwrap();
        let ee = plan["ee_pos"].as_array().unwrap();
        assert_eq!(frames.len(), ee.len());
        assert_eq!(t["reached"], plan["reached"]);
        for (f, e) in frames.iter().zip(ee) {
            let f = f.as_array().unwrap();
            assert_eq!(f.len(), 7, "6 joint origins and the tip");
            for k in 0..3 {
                assert!((f[6][k].as_f64().unwrap() - e[k].as_f64().unwrap()).abs() <= 0.6e-4);
            }
        }
    }

    let (console, dom, canvas) = show(&page, &dir);
    assert!(console.is_empty(), "console messages: {console:#?}");
    assert!(dom.contains("<span id=\"info\">step "), "the script did not run: {dom}");
    assert_eq!(dom.matches("<option value=").count(), 4, "{dom}");
    assert!(
        canvas.drawn > 5_000 && canvas.colours > 100 && canvas.saturated > 500,
        "blank canvas: {canvas:?}"
    );

    // `plan --view`: the Jacobian controller's plan in one view.
    let planned = dir.join("plan.html");
    let o = bin()
        .args(["plan", "--controller", "jacobian", "--target", "0.4,0.2,0.3", "--format", "jsonl"])
        .args(["--view", planned.to_str().unwrap()])
        .output()
        .unwrap();
    let rows = ok(o).lines().count();
    let data = view_data(&std::fs::read_to_string(&planned).unwrap());
    assert_eq!(data["trajectories"][0]["frames"].as_array().unwrap().len(), rows - 1);
    let (console, dom, canvas) = show(&planned, &dir);
    assert!(dom.contains("<span id=\"info\">step ") && dom.contains(">plan (reached)<"), "{dom}");
    assert!(console.is_empty(), "console messages: {console:#?}");
    assert!(
        canvas.drawn > 5_000 && canvas.colours > 100 && canvas.saturated > 500,
        "blank canvas: {canvas:?}"
    );

    // The same checks catch a page whose script fails.
    let broken = dir.join("broken.html");
    std::fs::write(&broken, html.replace("\"trajectories\":[", "\"trajectories\":[}")).unwrap();
    let (console, dom, canvas) = show(&broken, &dir);
    assert!(console.iter().any(|l| l.contains("Uncaught SyntaxError")), "{console:#?}");
    assert!(
        !dom.contains("<span id=\"info\">step ") && canvas.drawn < 1000 && canvas.saturated == 0,
        "{canvas:?}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
