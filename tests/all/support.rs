//! Helpers: run the binary, make edited copies of the shipped files in a temporary folder.

use binpick::config::LoadedScene;
use binpick::planning::PlanOptions;
use binpick::reference::{PlannerCase, fig5_cases};
use binpick::robot::{JointVector, RobotModel};
use std::path::{Path, PathBuf};
use std::process::Output;

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs `binpick ARGS` in `dir`.
pub fn binpick_in(dir: &Path, args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_binpick"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("binpick runs")
}

/// Runs `binpick ARGS` in the repository root.
pub fn binpick(args: &[&str]) -> Output {
    binpick_in(&repo(), args)
}

/// stdout as text.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A temporary folder, removed with everything in it when dropped. Written here rather than
/// taken from a crate: a dev-dependency would change the features of crates the release build
/// shares (tempfile turns on rustix's `fs`, which rebuilds rerun's chain), and the README's test
/// command reuses the release build's dependencies as they are.
pub struct TempDir(PathBuf);

impl TempDir {
    /// The folder's path.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A new empty folder under the system's temporary folder, unique to this process and call.
pub fn tempdir() -> std::io::Result<TempDir> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    loop {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let p = std::env::temp_dir().join(format!("binpick-test-{}-{n}", std::process::id()));
        match std::fs::create_dir(&p) {
            Ok(()) => return Ok(TempDir(p)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
}

/// A temporary folder holding the shipped scene, URDF and workpieces, to edit copies of.
pub struct Workspace {
    /// Keeps the folder alive.
    pub dir: TempDir,
}

impl Workspace {
    /// Copies `scenes/` and `workpieces/` into a new temporary folder.
    pub fn new() -> Self {
        let dir = tempdir().expect("tempdir");
        for sub in ["scenes", "workpieces"] {
            std::fs::create_dir_all(dir.path().join(sub)).unwrap();
            for e in std::fs::read_dir(repo().join(sub)).unwrap() {
                let p = e.unwrap().path();
                std::fs::copy(&p, dir.path().join(sub).join(p.file_name().unwrap())).unwrap();
            }
        }
        Workspace { dir }
    }

    /// Path of a file in the workspace.
    pub fn path(&self, rel: &str) -> PathBuf {
        self.dir.path().join(rel)
    }

    /// Replaces `from` by `to` in `rel` (which must contain `from`), writing it as `out`.
    pub fn edit(&self, rel: &str, out: &str, from: &str, to: &str) -> PathBuf {
        let text = std::fs::read_to_string(self.path(rel)).unwrap();
        assert!(text.contains(from), "{rel} does not contain {from:?}");
        let p = self.path(out);
        std::fs::write(&p, text.replacen(from, to, 1)).unwrap();
        p
    }

    /// Every file below the workspace, sorted.
    pub fn listing(&self) -> Vec<PathBuf> {
        fn walk(p: &Path, out: &mut Vec<PathBuf>) {
            for e in std::fs::read_dir(p).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    walk(&p, out);
                } else {
                    out.push(p);
                }
            }
        }
        let mut v = Vec::new();
        walk(self.dir.path(), &mut v);
        v.sort();
        v
    }
}

/// The Fig. 5 planner cases, each with the via points our planner finds for it (planner stream
/// seeded by the case's index): the paths the trajectory and execution tests run on.
pub fn planned_fig5_paths(scene: &LoadedScene, robot: &RobotModel) -> Vec<(PlannerCase, Vec<JointVector>)> {
    fig5_cases(&scene.scene, robot)
        .unwrap()
        .into_iter()
        .enumerate()
        .map(|(k, case)| {
            let mut rng = binpick::rng::stream(k as u64, "planner");
            let plan = case
                .model
                .plan(&case.start, &case.goal, &PlanOptions::default(), &mut rng)
                .unwrap();
            let via = plan.waypoints.iter().map(|q| JointVector::from(*q)).collect();
            (case, via)
        })
        .collect()
}

/// The servo's limit check on what it was asked for: every tick's demanded torque (before the
/// drive's saturation) within each joint's limit, and every tracking error within the servo's
/// tolerance. Returns the largest demand / limit and error / tolerance, or the first tick beyond.
pub fn demand_check(
    robot: &RobotModel,
    servo: &binpick::servo::Servo,
    trace: &[binpick::servo::Tick],
) -> Result<(f64, f64), String> {
    let limit = robot.torque_limit_nm();
    let (mut demand, mut error) = (0.0f64, 0.0f64);
    for t in trace {
        for i in 0..binpick::robot::DOF {
            let d = t.demand_nm[i].abs() / limit[i];
            let e = t.error_rad[i].abs() / servo.tolerance_rad;
            if d > 1.0 {
                return Err(format!(
                    "t = {:.3} s: J{} demanded {:.1} % of its torque limit",
                    t.t_s,
                    i + 1,
                    100.0 * d
                ));
            }
            if e > 1.0 {
                return Err(format!(
                    "t = {:.3} s: J{} tracking error {:.3} deg beyond the tolerance",
                    t.t_s,
                    i + 1,
                    t.error_rad[i].to_degrees()
                ));
            }
            demand = demand.max(d);
            error = error.max(e);
        }
    }
    Ok((demand, error))
}

/// The twelve outward-wound triangles of a box whose eight corners are numbered by their bits
/// (bit 0: +x, bit 1: +y, bit 2: +z), as the mesh tests write boxes into OBJ files.
pub const BOX_TRIANGLES: [[usize; 3]; 12] = [
    [0, 2, 3],
    [0, 3, 1],
    [4, 5, 7],
    [4, 7, 6],
    [0, 1, 5],
    [0, 5, 4],
    [2, 6, 7],
    [2, 7, 3],
    [0, 4, 6],
    [0, 6, 2],
    [1, 3, 7],
    [1, 7, 5],
];

/// A two-pick batch with `args` exits 2 naming `bad.toml` and `why`, without a panic, and
/// writes nothing.
pub fn batch_is_refused(ws: &Workspace, args: &[&str], why: &str) {
    let out = ws.path("runs");
    let mut all = vec![
        "batch",
        "--picks",
        "2",
        "--deterministic",
        "--out",
        out.to_str().unwrap(),
    ];
    all.extend_from_slice(args);
    let o = binpick_in(ws.dir.path(), &all);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert!(
        err.contains("bad.toml") && err.contains(why) && !err.contains("panicked"),
        "{args:?}: {err}"
    );
    assert!(!out.exists(), "{args:?} wrote {}", out.display());
}

/// A two-pick sweep setting the cell's key `set` (`KEY=V1,V2`) over `workpiece`, whose file
/// (`bad.toml`) brings that key itself, exits 2 saying the key does not reach it, and writes
/// nothing.
pub fn cell_sweep_is_refused(ws: &Workspace, set: &str, workpiece: &Path) {
    let out = ws.path("runs");
    let o = binpick_in(
        ws.dir.path(),
        &[
            "sweep",
            "--set",
            set,
            "--workpieces",
            workpiece.to_str().unwrap(),
            "--picks",
            "2",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("bad.toml") && err.contains("does not reach this workpiece"),
        "{err}"
    );
    assert!(!out.exists(), "the refused sweep wrote {}", out.display());
}

/// A workpiece file's text without its `[gripper]` section (up to the next blank line).
pub fn without_cup_section(text: &str) -> String {
    match text.find("[gripper]") {
        Some(start) => {
            let end = text[start..].find("\n\n").map_or(text.len(), |i| start + i + 1);
            format!("{}{}", &text[..start], &text[end..])
        }
        None => text.to_string(),
    }
}
