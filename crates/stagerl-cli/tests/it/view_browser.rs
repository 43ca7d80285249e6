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
    let data = common::view_data(&html);
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
    let data = common::view_data(&std::fs::read_to_string(&planned).unwrap());
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

/// The pixels in which two screenshots of the same size differ.
fn differing_pixels(a: &Path, b: &Path) -> usize {
    let read = |p: &Path| {
        let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(p).unwrap()));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        buf.truncate(info.buffer_size());
        (buf, info.color_type.samples())
    };
    let ((a, n), (b, _)) = (read(a), read(b));
    a.chunks(n).zip(b.chunks(n)).filter(|(x, y)| x[..3] != y[..3]).count()
}

#[test]
fn names_from_the_urdf_are_text_and_the_scene_is_drawn() {
    let dir = scratch("view-browser-scene");
    std::fs::create_dir_all(dir.join("run")).unwrap();
    // An arm whose links are named to close the data's script and run one of their own.
    let evil = |k: u32| {
        format!("&lt;/script&gt;&lt;script&gt;document.body.setAttribute('data-pwned','{k}')&lt;/script&gt;")
    };
    let urdf = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets/robots/ur5.urdf"))
        .unwrap()
        .replace("\"tool0\"", &format!("\"{}\"", evil(1)))
        .replace("\"wrist_2_link\"", &format!("\"{}w2\"", evil(2)))
        .replace("\"wrist_3_link\"", &format!("\"{}w3\"", evil(3)));
    let urdf_path = dir.join("evil.urdf");
    std::fs::write(&urdf_path, urdf).unwrap();
    std::fs::write(
        dir.join("run/config.toml"),
        format!("[robot]\nurdf = {:?}\n", urdf_path.to_str().unwrap()),
    )
    .unwrap();
    // A ball across the straight way (the Jacobian controller touches it) and a turned box.
    let requests = dir.join("requests.jsonl");
    std::fs::write(
        &requests,
        concat!(
            "{\"target\":[-0.4,0.1,0.35],\"obstacles\":[{\"shape\":\"sphere\",\"radius_m\":0.04,",
            "\"position_m\":[-0.4435,-0.0046,0.391]},{\"shape\":\"cuboid\",\"half_extents_m\":[0.05,0.1,0.02],",
            "\"position_m\":[-0.2,-0.3,0.3],\"rotation_xyzw\":[0,0,0.3826834,0.9238795]}]}\n"
        ),
    )
    .unwrap();
    let page = dir.join("scene.html");
    let run = dir.join("run");
    ok(bin()
        .args(["plan", "--run", run.to_str().unwrap(), "--planner", "jacobian"])
        .args(["--targets", requests.to_str().unwrap(), "--view", page.to_str().unwrap()])
        .output()
        .unwrap());
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(!html.contains("</script><script>"), "a name closes the data's script");
    let data = common::view_data(&html);
    let t = &data["trajectories"][0];
    assert_eq!(t["obstacles"].as_array().unwrap().len(), 2);
    assert_eq!(t["collision"], true);
    assert!(
        t["min_clearance_m"].as_f64().unwrap() < 0.0 && t["closest"]["distance_m"].as_f64().unwrap() < 0.0
    );
    assert!(t["contact"]["what"].as_str().unwrap().contains("data-pwned"), "{t}");

    // Paused on the step after the contact: the names are shown as text, no script of theirs ran.
    let at = |p: &Path| PathBuf::from(format!("{}#traj=1&step=2&paused", p.display()));
    let (console, dom, canvas) = show(&at(&page), &dir);
    assert!(console.is_empty(), "console messages: {console:#?}");
    assert!(dom.contains("<span id=\"info\">step 2 / "), "the script did not run: {dom}");
    assert!(!dom.contains("data-pwned=\""), "a name ran as script: {dom}");
    assert!(dom.contains("arm: base_link to &lt;/script&gt;&lt;script&gt;document.body"), "{dom}");
    assert!(dom.contains("contact at step 1: link `&lt;/script&gt;&lt;script&gt;"), "{dom}");
    assert!(dom.contains("min clearance -0.0"), "{dom}");
    assert!(canvas.drawn > 5_000 && canvas.saturated > 500, "blank canvas: {canvas:?}");

    // The obstacles are drawn: the same page without them differs in many pixels.
    let mut bare = data.clone();
    bare["trajectories"][0]["obstacles"] = Value::Array(Vec::new());
    let json = serde_json::to_string(&bare).unwrap().replace('<', "\\u003c");
    let start = html.find("type=\"application/json\">").unwrap() + "type=\"application/json\">".len();
    let end = start + html[start..].find("</script>").unwrap();
    let bare_page = dir.join("bare.html");
    std::fs::write(&bare_page, format!("{}{json}{}", &html[..start], &html[end..])).unwrap();
    let (console, _, _) = show(&at(&bare_page), &dir);
    assert!(console.is_empty(), "console messages: {console:#?}");
    let diff = differing_pixels(&dir.join("scene.png"), &dir.join("bare.png"));
    assert!(diff > 1_000, "the obstacles drew {diff} pixels");
    std::fs::remove_dir_all(&dir).ok();
}
