//! The cell as a tune's evaluator: each round's candidates resolved like a sweep's variants and
//! run as one study on the training seeds; the best and the untuned cell run on the test seeds.
//!
//! Job: check the varied keys against the resolved files (a key the cell or workpiece file does
//! not hold, or holds as anything but a number, is bad input; an integer there makes the key an
//! integer key, whose bounds must be whole); resolve each candidate through
//! [`crate::sweep::resolve`](mod@crate::sweep::resolve) (the checks a cell file goes through: a candidate they refuse is
//! [`Outcome::Refused`], never run); run the round's new candidates as one study through
//! [`crate::study::run_study`] (in parallel), answer repeated candidates and those in the
//! [`Journal`] without running them, and append each candidate to the journal as soon as all its
//! runs finished. A run ended by Ctrl-C is not journalled. The varied keys the files may leave
//! out are checked against the values the untuned cell runs with: a workpiece's cup and hopper
//! recipe keys (`workpiece.gripper.*`, `workpiece.feeder.*`: the cell's where it brings none)
//! and the grid's slot spacing
//! (`place_tray.pitch_x_m`, `pitch_y_m`: the footprint plus the gap where the cell gives none).
//!
//! Shards ([`Cell::shard`], `tune --shard K/N`): of each round's new candidates, shard K runs
//! those at places K-1, K-1+N, ... in the round (as [`crate::study::shard`] splits a study's
//! runs) and waits for the others' figures in its peers' journals ([`Peers`]); the two test
//! measurements are split the same way. Every shard thus answers every candidate with the same
//! figures (read back exactly) and its optimizer asks for the same next round.
//!
//! Units: the files' own; s and counts in the figures.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::AtomicBool;

use super::journal::Journal;
use super::{Dim, Evaluator, Figures, Objective, Outcome};
use crate::cycle::{EndReason, Tally};
use crate::study::{Resolved, RunSettings, StudyError, StudyRun, StudySpec, run_study};
use crate::sweep::{Segment, SetArg};

/// The value at `path` in a TOML tree, if there is one.
fn lookup<'a>(mut v: &'a toml::Value, path: &[Segment]) -> Option<&'a toml::Value> {
    for s in path {
        v = match s {
            Segment::Key(k) => v.as_table()?.get(k)?,
            Segment::Index(i) => v.as_array()?.get(*i)?,
        };
    }
    Some(v)
}

/// The untuned cell and workpiece, resolved as a sweep resolves them.
pub fn base(scene: Option<&Path>, workpiece: &str) -> Result<Resolved, StudyError> {
    crate::sweep::resolve(scene, &[workpiece.to_string()], &[], &[Vec::new()])
}

/// Checks each key against the resolved (defaults filled in) cell and workpiece files: it must
/// hold a number there; an integer makes the key an integer key (its bounds must be whole).
pub fn check_keys(base: &Resolved, dims: &mut [Dim]) -> Result<(), StudyError> {
    let v = &base.variants[0];
    let as_tree = |what: &str, r: Result<toml::Value, toml::ser::Error>| {
        r.map_err(|e| StudyError::Run(format!("the resolved {what} does not serialise: {e}")))
    };
    // The grid's slot spacing holds the spacing the workpiece gets where the cell gives none, so
    // `place_tray.pitch_x_m` can be varied from the cell's own.
    let mut cell = v.scene.scene.clone();
    let w0 = &v.workpieces[0].workpiece;
    if cell.place_tray.pattern == crate::config::SlotPattern::Grid {
        let [px, py] = cell.place_tray.pitch_m([w0.size_m[0], w0.size_m[1]]);
        cell.place_tray.pitch_x_m.get_or_insert(px);
        cell.place_tray.pitch_y_m.get_or_insert(py);
    }
    let scene = as_tree("cell", toml::Value::try_from(&cell))?;
    // The workpiece's cup, hopper recipe and shake keys hold the cell's values where it brings
    // none of its own, so a `workpiece.gripper.`, `workpiece.feeder.` or `workpiece.agitation.`
    // key can be varied on any workpiece.
    let mut w = v.workpieces[0].workpiece.clone();
    w.gripper = Some(w.gripper.unwrap_or_default().completed(&v.scene.scene.gripper));
    w.feeder = Some(w.feeder.unwrap_or_default().completed(&v.scene.scene.feeder));
    w.agitation = Some(w.agitation.unwrap_or_default().completed(&v.scene.scene.agitation));
    let wp = as_tree("workpiece", toml::Value::try_from(&w))?;
    for d in dims.iter_mut() {
        let (target, path) = d.target();
        let (tree, file) = match target {
            crate::sweep::Target::Cell => (&scene, &v.scene.label),
            crate::sweep::Target::Workpiece => (&wp, &v.workpieces[0].label),
        };
        let bad = |m: String| StudyError::Input(format!("--vary {}: {m}", d.key));
        match lookup(tree, &path) {
            None => return Err(bad(format!("{file} has no such key"))),
            Some(toml::Value::Integer(_)) => {
                if d.lo.fract() != 0.0 || d.hi.fract() != 0.0 {
                    return Err(bad(format!(
                        "the key takes whole numbers, so its range must be whole numbers, got {}:{}",
                        d.lo, d.hi
                    )));
                }
                d.integer = true;
            }
            Some(toml::Value::Float(_)) => d.integer = false,
            Some(other) => {
                return Err(bad(format!(
                    "not a numeric key: {file} holds {} there",
                    crate::sweep::value_text(other)
                )));
            }
        }
    }
    Ok(())
}

/// Values as the files write them (the journal's and the spec's keys).
pub fn texts(dims: &[Dim], values: &[f64]) -> Vec<String> {
    dims.iter()
        .zip(values)
        .map(|(d, x)| crate::sweep::value_text(&d.value(*x)))
        .collect()
}

/// Joins resolved studies into one (their arm models kept, indices shifted).
fn join(label: &str, parts: Vec<Resolved>) -> Resolved {
    let mut out = Resolved {
        variants: Vec::new(),
        robots: Vec::new(),
        scene_label: label.to_string(),
    };
    for p in parts {
        let shift = out.robots.len();
        out.variants.extend(p.variants.into_iter().map(|mut v| {
            v.robot += shift;
            v
        }));
        out.robots.extend(p.robots);
    }
    out
}

/// The cell evaluating a tune's candidates.
pub struct Cell<'a> {
    /// The cell file (none: the embedded default).
    pub scene: Option<&'a Path>,
    /// The workpiece as given (a name or a path).
    pub workpiece: String,
    /// The keys.
    pub dims: Vec<Dim>,
    /// Training seeds.
    pub train_seeds: Vec<u64>,
    /// Picks per run.
    pub picks: usize,
    /// Fixed compute budgets.
    pub deterministic: bool,
    /// Worker threads.
    pub threads: usize,
    /// Set by Ctrl-C.
    pub stop: Option<&'static AtomicBool>,
    /// The takt the figures' `takt_s` is (the objective).
    pub objective: Objective,
    /// The journal.
    pub journal: &'a Journal,
    /// Called after each run.
    pub progress: &'a (dyn Fn(&StudyRun) + Sync),
    /// Candidates answered from the journal (each counted once).
    pub replayed: usize,
    /// Cell runs made.
    pub runs: usize,
    /// Figures known: the journal's and those run here.
    memo: HashMap<Vec<String>, Figures>,
    /// Values answered from the journal so far.
    from_journal: std::collections::HashSet<Vec<String>>,
    /// Test figures known: the journal's and those run here.
    test_memo: HashMap<super::journal::TestKey, Figures>,
    /// This process's shard `(k, n)` of each round's runs: `(1, 1)` runs them all.
    pub shard: (usize, usize),
    /// Where the other shards' figures are read from (sharded tunes only).
    pub peers: Option<Peers>,
}

/// The other shards of a sharded tune: their journals beside this one's in the shared folder.
#[derive(Debug, Clone)]
pub struct Peers {
    /// The folder every shard writes its journal into.
    pub dir: std::path::PathBuf,
    /// The journals' common stem (the tune's name).
    pub stem: String,
    /// The tune's identity.
    pub header: super::journal::Header,
    /// How often the peers' journals are read while waiting.
    pub poll: std::time::Duration,
    /// How long to wait for a peer's figures at most (s).
    pub timeout_s: f64,
}

/// Who runs item `i` of a round's new work in shard `(k, n)`: every n-th from the (k-1)-th, as
/// [`crate::study::shard`] splits a study's runs.
fn mine(i: usize, (k, n): (usize, usize)) -> bool {
    i % n == k - 1
}

impl<'a> Cell<'a> {
    /// The evaluator; its memo starts with the journal's entries.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        scene: Option<&'a Path>,
        workpiece: String,
        dims: Vec<Dim>,
        train_seeds: Vec<u64>,
        picks: usize,
        deterministic: bool,
        threads: usize,
        journal: &'a Journal,
        progress: &'a (dyn Fn(&StudyRun) + Sync),
    ) -> Self {
        Cell {
            scene,
            workpiece,
            dims,
            train_seeds,
            picks,
            deterministic,
            threads,
            stop: None,
            objective: Objective::default(),
            journal,
            progress,
            replayed: 0,
            runs: 0,
            memo: journal.entries.clone(),
            from_journal: Default::default(),
            test_memo: journal.tests.clone(),
            shard: (1, 1),
            peers: None,
        }
    }

    /// Reads the peers' journals into the memos; `Ok(false)` when there are no peers.
    fn read_peers(&mut self) -> Result<bool, StudyError> {
        let Some(p) = &self.peers else { return Ok(false) };
        let e = super::journal::read_peers(&p.dir, &p.stem, &p.header, self.journal.path())?;
        for (k, f) in e.train {
            self.memo.entry(k).or_insert(f);
        }
        for (k, f) in e.test {
            self.test_memo.entry(k).or_insert(f);
        }
        Ok(true)
    }

    /// Waits until `known` holds for every key in `keys`, reading the peers' journals; fails when
    /// Ctrl-C was pressed or the peers' timeout passes.
    fn wait_for<K>(&mut self, keys: &[K], known: impl Fn(&Self, &K) -> bool) -> Result<(), StudyError> {
        let start = std::time::Instant::now();
        loop {
            if keys.iter().all(|k| known(self, k)) {
                return Ok(());
            }
            if !self.read_peers()? {
                return Err(StudyError::Run("a candidate of another shard, but no peers".into()));
            }
            if keys.iter().all(|k| known(self, k)) {
                return Ok(());
            }
            if self.stop.is_some_and(|s| s.load(std::sync::atomic::Ordering::Relaxed)) {
                return Err(StudyError::Run("interrupted".into()));
            }
            let p = self.peers.as_ref().expect("read above");
            if start.elapsed().as_secs_f64() > p.timeout_s {
                let missing = keys.iter().filter(|k| !known(self, k)).count();
                return Err(StudyError::Run(format!(
                    "shard {}/{}: {missing} evaluation(s) of the other shards did not appear in their journals ({}/{}.*journal.jsonl) within {} s; run the missing shards (each resumes from its journal) and this one again",
                    self.shard.0,
                    self.shard.1,
                    p.dir.display(),
                    p.stem,
                    p.timeout_s
                )));
            }
            std::thread::sleep(p.poll);
        }
    }

    /// One candidate resolved and checked.
    pub fn resolve(&self, values: &[f64]) -> Result<Resolved, StudyError> {
        let sets: Vec<SetArg> = self
            .dims
            .iter()
            .map(|d| {
                let (target, path) = d.target();
                SetArg {
                    key: d.key.clone(),
                    target,
                    path,
                    values: Vec::new(),
                }
            })
            .collect();
        let vals: Vec<toml::Value> = self.dims.iter().zip(values).map(|(d, x)| d.value(*x)).collect();
        crate::sweep::resolve(self.scene, std::slice::from_ref(&self.workpiece), &sets, &[vals])
    }

    /// Runs `resolved`'s variants (labelled `rows`) on `seeds` as one study; returns each
    /// variant's figures, in order. `journal` appends each variant's figures as it finishes.
    fn study(
        &mut self,
        resolved: &Resolved,
        rows: Vec<Vec<String>>,
        seeds: &[u64],
        journal: bool,
    ) -> Result<Vec<Figures>, StudyError> {
        let spec = StudySpec {
            scene: resolved.scene_label.clone(),
            keys: self.dims.iter().map(|d| d.key.clone()).collect(),
            variants: rows.clone(),
            workpieces: vec![resolved.variants[0].workpieces[0].workpiece.name.clone()],
            seeds: seeds.to_vec(),
            picks: self.picks,
            deterministic: self.deterministic,
        };
        let jobs = spec.jobs();
        let done: Mutex<Vec<Vec<Tally>>> = Mutex::new(vec![Vec::new(); rows.len()]);
        let failed: Mutex<Option<StudyError>> = Mutex::new(None);
        let progress = self.progress;
        let journal_to = self.journal;
        let objective = self.objective;
        let on_run = |r: &StudyRun| {
            progress(r);
            let Ok(mut done) = done.lock() else { return };
            let mine = &mut done[r.variant];
            mine.push(r.tally.clone());
            let interrupted = mine.iter().any(|t| t.ended == Some(EndReason::Interrupted));
            if journal && mine.len() == seeds.len() && !interrupted {
                let f = Figures::of(&Tally::merged(mine.iter()).expect("one run at least"), objective);
                if let Err(e) = journal_to.append(&rows[r.variant], &f)
                    && let Ok(mut slot) = failed.lock()
                {
                    slot.get_or_insert(e);
                }
            }
        };
        let settings = RunSettings {
            threads: self.threads,
            record: None,
            stop: self.stop,
        };
        let runs = run_study(resolved, &spec, &jobs, &settings, &on_run)?;
        self.runs += runs.len();
        if let Some(e) = failed.into_inner().ok().flatten() {
            return Err(e);
        }
        if runs.iter().any(|r| r.tally.ended == Some(EndReason::Interrupted)) {
            return Err(StudyError::Run("interrupted".into()));
        }
        Ok((0..rows.len())
            .map(|v| {
                let t = Tally::merged(runs.iter().filter(|r| r.variant == v).map(|r| &r.tally));
                Figures::of(&t.expect("every variant has runs"), self.objective)
            })
            .collect())
    }

    /// The best candidate and the untuned cell on `seeds` (the test seeds): their figures. Each
    /// goes to the journal; a shard runs its share of the two (the best the first shard's, the
    /// untuned cell the second's) and reads the other from its peer's journal.
    pub fn test(&mut self, best: &[f64], seeds: &[u64]) -> Result<(Figures, Figures), StudyError> {
        self.read_peers()?;
        let rows = [texts(&self.dims, best), vec!["untuned".to_string(); self.dims.len()]];
        let keys: Vec<super::journal::TestKey> = rows.iter().map(|r| (r.clone(), seeds.to_vec())).collect();
        let todo: Vec<usize> = (0..2)
            .filter(|&i| !self.test_memo.contains_key(&keys[i]) && mine(i, self.shard))
            .collect();
        if !todo.is_empty() {
            let mut parts = Vec::new();
            for &i in &todo {
                parts.push(if i == 0 {
                    self.resolve(best)?
                } else {
                    base(self.scene, &self.workpiece)?
                });
            }
            let label = parts[0].scene_label.clone();
            let both = join(&label, parts);
            let f = self.study(&both, todo.iter().map(|&i| rows[i].clone()).collect(), seeds, false)?;
            for (&i, f) in todo.iter().zip(f) {
                self.journal.append_test(&rows[i], seeds, &f)?;
                self.test_memo.insert(keys[i].clone(), f);
            }
        }
        self.wait_for(&keys, |c, k| c.test_memo.contains_key(k))?;
        Ok((self.test_memo[&keys[0]].clone(), self.test_memo[&keys[1]].clone()))
    }
}

impl Evaluator for Cell<'_> {
    fn evaluate(&mut self, _round: usize, candidates: &[Vec<f64>]) -> Result<Vec<Outcome>, StudyError> {
        // A shard first takes what its peers have finished.
        self.read_peers()?;
        let mut outcomes: Vec<Option<Outcome>> = vec![None; candidates.len()];
        let mut to_run: Vec<(Vec<String>, Resolved)> = Vec::new();
        // A shard's share: the round's new candidates by their place in the round; the others'
        // figures come from their journals.
        let mut theirs: Vec<Vec<String>> = Vec::new();
        for (i, c) in candidates.iter().enumerate() {
            let key = texts(&self.dims, c);
            if let Some(f) = self.memo.get(&key) {
                if self.journal.entries.contains_key(&key) && self.from_journal.insert(key.clone()) {
                    self.replayed += 1;
                }
                outcomes[i] = Some(Outcome::Measured(f.clone()));
            } else if to_run.iter().any(|(k, _)| k == &key) || theirs.contains(&key) {
                // Asked twice in this round: run once (filled in below).
            } else {
                match self.resolve(c) {
                    Ok(_) if !mine(i, self.shard) => theirs.push(key),
                    Ok(r) => to_run.push((key, r)),
                    Err(StudyError::Config(e)) => outcomes[i] = Some(Outcome::Refused(e.to_string())),
                    Err(e) => return Err(e),
                }
            }
        }
        if !to_run.is_empty() {
            let label = to_run[0].1.scene_label.clone();
            let rows: Vec<Vec<String>> = to_run.iter().map(|(k, _)| k.clone()).collect();
            let resolved = join(&label, to_run.into_iter().map(|(_, r)| r).collect());
            let seeds = self.train_seeds.clone();
            let figures = self.study(&resolved, rows.clone(), &seeds, true)?;
            for (k, f) in rows.into_iter().zip(figures) {
                self.memo.entry(k).or_insert(f);
            }
        }
        self.wait_for(&theirs, |c, k| c.memo.contains_key(k))?;
        Ok(candidates
            .iter()
            .zip(outcomes)
            .map(|(c, o)| o.unwrap_or_else(|| Outcome::Measured(self.memo[&texts(&self.dims, c)].clone())))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_workpiece_cup_key_can_be_varied_on_a_workpiece_that_brings_no_cup() {
        let base = base(None, "B").unwrap();
        let mut dims = vec![super::super::parse_vary("workpiece.gripper.cup_diameter_m=0.004:0.02").unwrap()];
        check_keys(&base, &mut dims).unwrap();
        assert!(!dims[0].integer);
        // Negative control: the tool body is the cell's, not a workpiece key.
        let mut dims = vec![super::super::parse_vary("workpiece.gripper.tool_length_m=0.1:0.2").unwrap()];
        let e = check_keys(&base, &mut dims).unwrap_err().to_string();
        assert!(e.contains("has no such key"), "{e}");
    }

    #[test]
    fn the_slot_spacing_and_the_waiting_pose_can_be_varied_from_the_cells_own() {
        let base = base(None, "B").unwrap();
        let mut dims = vec![
            super::super::parse_vary("place_tray.pitch_x_m=0.03:0.06").unwrap(),
            super::super::parse_vary("cycle.waiting_tool_m[2]=0.1:0.2").unwrap(),
        ];
        check_keys(&base, &mut dims).unwrap();
        assert!(dims.iter().all(|d| !d.integer));
    }
}
