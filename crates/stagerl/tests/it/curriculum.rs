//! The obstacle curriculum (`[train.curriculum]`) in real training runs: the stage of every
//! episode in `episodes.csv` (and TensorBoard) follows the schedule its success column implies,
//! the run is the same on any thread count, the column is absent without a curriculum, and the
//! configs it does not fit are refused by name.

use stagerl::agent::Algo;
use stagerl::config::{Config, CurriculumConfig};
use stagerl::io::checkpoint::Checkpoint;
use stagerl::run::dir::RunDir;
use stagerl::sim::scene::RandomObstacles;
use stagerl::train::train;

/// SAC among 1-3 random obstacles, small networks, 200 episodes; `curriculum` on top.
fn config(curriculum: Option<CurriculumConfig>) -> Config {
    let mut cfg = Config::default();
    cfg.agent.hidden = vec![32, 32];
    cfg.agent.batch_size = 64;
    cfg.agent.learning_starts = 300;
    cfg.task.observe_obstacles = true;
    cfg.task.random_obstacles = Some(RandomObstacles { count: [1, 3], ..RandomObstacles::default() });
    cfg.train.seed = 3;
    cfg.train.episodes = 200;
    cfg.train.eval_every_episodes = 100;
    cfg.train.eval_trials = 5;
    cfg.train.checkpoint_every_episodes = 40;
    cfg.train.curriculum = curriculum;
    cfg
}

/// An easy schedule (one success in 10 episodes advances), so that a short run goes through its
/// stages.
fn easy() -> CurriculumConfig {
    CurriculumConfig {
        window: 10,
        advance_at: 0.1,
        obstacles_in_path: vec![0.0, 0.5, 1.0],
        max_obstacles: vec![1, 2, 3],
    }
}

/// Train `cfg` into a scratch directory: the lines of `episodes.csv` (wall time cut), the
/// TensorBoard scalars and the final checkpoint.
fn run(cfg: &Config, tag: &str) -> (Vec<String>, Vec<(String, i64, f32)>, Checkpoint) {
    let dir = std::env::temp_dir().join(format!("stagerl-curriculum-{}-{tag}", std::process::id()));
    let summary = train(cfg, &dir, |_| {}).unwrap();
    let text = std::fs::read_to_string(RunDir::new(&dir).episodes()).unwrap();
    let rows = text.lines().map(|l| l.rsplit_once(',').unwrap().0.to_string()).collect();
    let mut tb = Vec::new();
    for f in stagerl::io::tensorboard::event_files(&RunDir::new(&dir).tb()).unwrap() {
        tb.extend(stagerl::io::tensorboard::read_scalars(&f).unwrap());
    }
    let ck = Checkpoint::load(&summary.final_checkpoint).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    (rows, tb, ck)
}

/// The stage of every episode as the schedule gives it from the episodes' successes, computed
/// here on its own: a stage ends after the episode at which its last `window` episodes (all of
/// the stage) hold at least `advance_at` successes; the last stage never ends.
fn expected_stages(c: &CurriculumConfig, successes: &[bool]) -> Vec<u32> {
    let (mut stage, mut begun, mut out) = (0usize, 0usize, Vec::new());
    for (i, _) in successes.iter().enumerate() {
        out.push(stage as u32);
        let played = i + 1 - begun;
        if stage + 1 < c.obstacles_in_path.len() && played >= c.window as usize {
            let last = &successes[i + 1 - c.window as usize..=i];
            let k = last.iter().filter(|&&s| s).count();
            if k as f64 / f64::from(c.window) >= c.advance_at {
                stage += 1;
                begun = i + 1;
            }
        }
    }
    out
}

#[test]
fn every_episode_is_played_at_the_stage_its_schedule_gives_and_reported() {
    let (rows, tb, _) = run(&config(Some(easy())), "schedule");
    assert_eq!(
        rows[0],
        "episode,reward,steps,success,final_distance_m,env_steps,collision_steps,curriculum_stage"
    );
    let fields: Vec<Vec<&str>> = rows[1..].iter().map(|r| r.split(',').collect()).collect();
    assert_eq!(fields.len(), 200);
    let success: Vec<bool> = fields.iter().map(|f| f[3] == "1").collect();
    let stages: Vec<u32> = fields.iter().map(|f| f[7].parse().unwrap()).collect();
    assert_eq!(stages, expected_stages(&easy(), &success));
    assert_eq!(stages.last(), Some(&2), "the run reached the last stage: {stages:?}");
    assert!(stages.iter().filter(|&&s| s == 2).count() > 10, "and stayed there: {stages:?}");
    // The same stages in TensorBoard, one scalar per episode.
    let logged: Vec<u32> =
        tb.iter().filter(|(t, _, _)| t == "train/curriculum_stage").map(|(_, _, v)| *v as u32).collect();
    assert_eq!(logged, stages);
}

#[test]
fn a_run_with_a_curriculum_is_the_same_on_any_thread_count_and_differs_from_one_without() {
    let mut cfg = config(Some(easy()));
    cfg.agent.hidden = vec![128, 128];
    cfg.agent.batch_size = 256;
    cfg.train.episodes = 100;
    let (a, _, ca) = run(&cfg, "threads-1");
    assert!(a.last().unwrap().ends_with(",1"), "the stage advanced: {:?}", a.last());
    let pool = stagerl::base::par::Pool::new(2).unwrap();
    let split = stagerl::base::par::split_jobs();
    let (b, _, cb) = stagerl::base::par::install(Some(&pool), || run(&cfg, "threads-2"));
    assert!(stagerl::base::par::split_jobs() > split + 100, "the updates were split");
    assert_eq!(a, b, "episodes.csv differs between 1 and 2 threads");
    assert!(ca.same_contents(&cb), "the final networks differ between 1 and 2 threads");
    // Without the curriculum: the default columns, and other episodes (stage 0 has at most one
    // obstacle where the task draws up to three).
    cfg.train.curriculum = None;
    let (plain, tb, _) = run(&cfg, "plain");
    assert_eq!(plain[0], "episode,reward,steps,success,final_distance_m,env_steps,collision_steps");
    assert!(tb.iter().all(|(t, _, _)| t != "train/curriculum_stage"));
    let strip = |rows: &[String]| {
        rows[1..].iter().map(|r| r.rsplit_once(',').unwrap().0.to_string()).collect::<Vec<_>>()
    };
    assert_ne!(strip(&a), plain[1..].to_vec(), "the curriculum changed nothing");
}

#[test]
fn configs_the_curriculum_does_not_fit_are_refused_naming_the_field() {
    let refused = |cfg: Config, field: &str, needle: &str| {
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains(&format!("`{field}`")) && e.contains(needle), "{e}");
    };
    config(Some(easy())).validate().unwrap();
    let mut ppo = config(Some(easy()));
    ppo.agent = stagerl::agent::AgentConfig::new(Algo::Ppo);
    refused(ppo, "train.curriculum", "agent.algo = \"ppo\"");
    let mut free = config(Some(easy()));
    free.task.random_obstacles = None;
    free.task.observe_obstacles = false;
    refused(free, "train.curriculum", "[task.random_obstacles]");
    let mut both = config(Some(easy()));
    both.train.obstacles_in_path = 0.5;
    refused(both, "train.obstacles_in_path", "[train.curriculum]");
    let over = config(Some(CurriculumConfig { max_obstacles: vec![1, 2, 4], ..easy() }));
    refused(over, "train.curriculum.max_obstacles", "[1, 3]");
    let short = config(Some(CurriculumConfig { max_obstacles: vec![1, 2], ..easy() }));
    refused(short, "train.curriculum.max_obstacles", "3 counts");
    // The same from a config file: the error names the field and the value.
    let text = "[task.random_obstacles]\ncount = [1, 3]\n[train.curriculum]\nadvance_at = 0\n";
    let e = Config::from_toml_str(text, std::path::Path::new("c.toml")).unwrap_err().to_string();
    assert!(e.contains("`train.curriculum.advance_at` = 0") && e.contains("(0, 1]"), "{e}");
    let e = Config::from_toml_str("[train.curriculum]\n", std::path::Path::new("c.toml")).unwrap_err();
    assert!(e.to_string().contains("[task.random_obstacles]"), "{e}");
}
