//! The worker's solves. Each fleet's network is solved whole on one solver thread while the
//! worker goes on mapping nodes (a node that brings a closure or a fix has its chain's
//! window re-solved at once, in `slam`); the solve comes back as a correction, and its points
//! (the last node when it was taken, the last when it was applied) are committed before
//! it is shown, so a replay takes and applies it at the same nodes. An operator's request
//! waits for the fleet's solve that is out, then solves on the worker itself. A recording's
//! feed takes and applies each solve where the recorded mapper did.

use super::Worker;
use crate::inbox::{OptimizeError, OptimizeReply};
use crate::journal::SiteFault;
use crate::views::Metrics;
use fleetmap::SolvePoint;
use serde_json::json;
use slam::{BackgroundSolve, SolvedInBackground};
use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A request about a fleet's solve, answered after the batch it came in.
pub(super) enum SolveRequest {
    /// Solve now (an operator, or a recording's solve without its taking point).
    Optimize(OptimizeReply),
    /// A recording's feed: take the solve here and run it; it waits for its `Apply`.
    Take(tokio::sync::oneshot::Sender<Result<(), OptimizeError>>),
    /// A recording's feed: apply the solve taken before.
    Apply(OptimizeReply),
}

/// A solve on its way to the solver thread.
struct Job {
    fleet: String,
    taken_after: u64,
    solve: BackgroundSolve,
}

/// A solve that ran.
pub(super) struct Done {
    fleet: String,
    taken_after: u64,
    solved: SolvedInBackground,
}

/// The solver thread and the solves that are out.
pub(super) struct Solving {
    jobs: Option<mpsc::Sender<Job>>,
    done: mpsc::Receiver<Done>,
    thread: Option<JoinHandle<()>>,
    /// Fleets with a solve on the solver thread.
    out: HashMap<String, Instant>,
    /// When each fleet's last solve was taken.
    last_taken: HashMap<String, Instant>,
    /// A recording's feed: solves taken and run, waiting for their applying point.
    held: HashMap<String, Done>,
    /// Per fleet, solves still on the solver thread for a map dropped since (cluster mode):
    /// they come back first, in order, and are thrown away.
    stale: HashMap<String, usize>,
    /// Solves that came back for a site whose entries wait for a commit: applied once they
    /// are durable, after them.
    deferred: Vec<Done>,
}

impl Solving {
    /// Starts the solver thread.
    pub(super) fn start() -> Solving {
        let (jobs, taken) = mpsc::channel::<Job>();
        let (finished, done) = mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("levelmap-solver".into())
            .spawn(move || {
                lower_priority();
                for job in taken {
                    let solved = job.solve.run();
                    let done = Done {
                        fleet: job.fleet,
                        taken_after: job.taken_after,
                        solved,
                    };
                    if finished.send(done).is_err() {
                        break;
                    }
                }
            })
            .expect("the solver thread starts");
        Solving {
            jobs: Some(jobs),
            done,
            thread: Some(thread),
            out: HashMap::new(),
            last_taken: HashMap::new(),
            held: HashMap::new(),
            stale: HashMap::new(),
            deferred: Vec::new(),
        }
    }

    /// Forgets a dropped fleet's solves: the one out will be thrown away when it is done.
    pub(super) fn forget(&mut self, fleet: &str) {
        if self.out.remove(fleet).is_some() {
            *self.stale.entry(fleet.to_owned()).or_default() += 1;
        }
        self.held.remove(fleet);
        self.last_taken.remove(fleet);
        self.deferred.retain(|d| d.fleet != fleet);
    }

    /// Whether `done` is a solve of a map dropped since (counted off).
    fn is_stale(&mut self, done: &Done) -> bool {
        match self.stale.get_mut(&done.fleet) {
            Some(n) if *n > 0 => {
                *n -= 1;
                true
            }
            _ => false,
        }
    }

    /// How long the worker may wait for work: briefly while a solve is out, so that it is
    /// applied soon after it is done.
    pub(super) fn wake(&self, interval: Duration) -> Duration {
        if self.out.is_empty() {
            interval
        } else {
            Duration::from_millis(5)
        }
    }

    /// Lets the solver thread finish its solve and stop.
    pub(super) fn stop(&mut self) {
        self.jobs = None;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The solver thread yields to the mapping thread and the network when the cores are busy:
/// nodes are shown and acked first, the whole network is solved with the time left.
fn lower_priority() {
    if let Err(e) = runtime::priority::lower_this_thread(SOLVER_NICE) {
        tracing::warn!("the solver thread keeps its priority: {e}");
    }
}

/// The solver thread's nice value.
const SOLVER_NICE: i32 = 10;

impl Worker {
    /// Applies the solves that came back; takes the solves that are due (at most one per
    /// fleet every solve interval, one out per fleet). Not while the store fails, nor for a
    /// site whose entries wait for a commit, and no timed solves while a recording is fed
    /// (it says where to solve).
    pub(super) fn due_solves(&mut self) {
        if self.store_stalled() {
            return;
        }
        let deferred = std::mem::take(&mut self.solving.deferred);
        let came_back = deferred
            .into_iter()
            .chain(std::iter::from_fn(|| self.solving.done.try_recv().ok()))
            .collect::<Vec<_>>();
        let mut came_back = came_back.into_iter();
        for done in came_back.by_ref() {
            if self.site_waits(&done.fleet) {
                self.solving.deferred.push(done);
            } else if self.apply_solve(done).is_err() {
                break;
            }
        }
        // Not applied this turn: kept, in order, for the next.
        self.solving.deferred.extend(came_back);
        if self.store_stalled() {
            return;
        }
        self.snapshots_due(false);
        if self.shared.feeding.load(Ordering::SeqCst) {
            return;
        }
        let interval = Duration::from_millis(self.config.solve_interval_ms);
        let mut ids: Vec<String> = self.fleets.keys().cloned().collect();
        ids.sort_unstable();
        for id in ids {
            let solving = &self.solving;
            let recent = solving
                .last_taken
                .get(&id)
                .is_some_and(|t| t.elapsed() < interval);
            if recent || solving.out.contains_key(&id) || self.site_waits(&id) {
                continue;
            }
            let Some(solve) = self.fleets.get_mut(&id).expect("listed").take_solve() else {
                continue;
            };
            let taken_after = solve.nodes() as u64 - 1;
            let job = Job {
                fleet: id.clone(),
                taken_after,
                solve,
            };
            let sent = self
                .solving
                .jobs
                .as_ref()
                .is_some_and(|jobs| jobs.send(job).is_ok());
            if !sent {
                tracing::error!(fleet = %id, "the solver thread is gone: no more solves");
                return;
            }
            let now = Instant::now();
            self.solving.out.insert(id.clone(), now);
            self.solving.last_taken.insert(id, now);
        }
    }

    /// Stops the solver thread once its solve is done, and applies the solves that came back
    /// (their points committed): then every fleet's snapshot can be written.
    pub(super) fn stop_solving(&mut self) {
        self.solving.stop();
        if self.unstored.is_some() {
            return;
        }
        let deferred = std::mem::take(&mut self.solving.deferred);
        for done in deferred {
            if self.apply_solve(done).is_err() {
                return;
            }
        }
        while let Ok(done) = self.solving.done.try_recv() {
            if self.apply_solve(done).is_err() {
                return;
            }
        }
        self.snapshots_due(true);
    }

    /// Whether a solve of `fleet` is out or held: its map's state lacks the solve's job.
    pub(super) fn solve_out(&self, fleet: &str) -> bool {
        self.solving.out.contains_key(fleet) || self.solving.held.contains_key(fleet)
    }

    /// Applies a solve that ran: its point committed, then the new view and the corrected
    /// poses. Whether it was applied (not while a part of the network is unanchored); an
    /// error when its point could not be made durable (it is kept to be committed again).
    fn apply_solve(&mut self, done: Done) -> Result<bool, String> {
        if self.solving.is_stale(&done) {
            return Ok(false);
        }
        let Done {
            fleet,
            taken_after,
            solved,
        } = done;
        let started = self.solving.out.remove(&fleet).unwrap_or_else(Instant::now);
        let map = self
            .fleets
            .get_mut(&fleet)
            .expect("a solve of a known fleet");
        match map.finish_solve(solved) {
            Ok(true) => {}
            Ok(false) => return Ok(false),
            Err(e) => {
                tracing::error!(fleet = %fleet, "optimization failed: {e}");
                return Ok(false);
            }
        }
        Metrics::bump(&self.shared.metrics.optimizations);
        let point = map.next_solve_point(taken_after);
        let work = super::Unstored {
            solves: vec![(fleet.clone(), point, map.take_pass_fixes())],
            ..Default::default()
        };
        match self.commit(&work).map(|faults| faults.into_iter().next()) {
            Err(e) => {
                self.store_failed(work, None);
                return Err(e.to_string());
            }
            Ok(Some((site, SiteFault::Fenced(_)))) => {
                let mut work = work;
                self.drop_site(&site, "another host appended to its log", &mut work.batch);
                return Ok(false);
            }
            Ok(Some((site, fault @ SiteFault::Unavailable(_)))) => {
                let why = format!("site {site}: {fault}");
                self.store_failed(work, Some([site].into()));
                return Err(why);
            }
            Ok(None) => {}
        }
        self.publish_solve(&fleet, started, &point);
        Ok(true)
    }

    /// A solve's new view, the corrected poses on the bus (with where the solve was taken),
    /// the `optimized` event.
    pub(super) fn publish_solve(&self, fleet: &str, started: Instant, point: &SolvePoint) {
        let map = &self.fleets[fleet];
        let ms = started.elapsed().as_secs_f64() * 1e3;
        self.shared.publish_map(map, ms);
        let solved_from = map.last_nodes_before(point.taken_after as usize + 1);
        self.bus.publish_poses(map, &solved_from);
        self.shared
            .event(&json!({"type": "optimized", "fleet": map.id()}));
    }

    /// Requests about solves, in the order they came.
    pub(super) fn solve_requests(&mut self, requests: Vec<(String, SolveRequest)>) {
        for (fleet, request) in requests {
            match request {
                SolveRequest::Optimize(reply) => {
                    let _ = reply.send(self.optimize_now(&fleet));
                }
                SolveRequest::Take(reply) => {
                    let _ = reply.send(self.take_held(&fleet));
                }
                SolveRequest::Apply(reply) => {
                    let held = self.solving.held.remove(&fleet);
                    let refused = || OptimizeError::Refused(format!("no solve of {fleet} taken"));
                    let _ = reply.send(held.ok_or_else(refused).and_then(|d| self.applied(d)));
                }
            }
        }
    }

    /// Solves `fleet` now, on the worker: after its solve that is out comes back.
    fn optimize_now(&mut self, fleet: &str) -> Result<serde_json::Value, OptimizeError> {
        let done = self.run_now(fleet)?;
        self.applied(done)
    }

    /// A recording's feed: takes `fleet`'s solve here and runs it, to apply at its point.
    fn take_held(&mut self, fleet: &str) -> Result<(), OptimizeError> {
        if self.solving.held.contains_key(fleet) {
            return Err(OptimizeError::Refused(format!(
                "a solve of {fleet} is held"
            )));
        }
        let done = self.run_now(fleet)?;
        self.solving.held.insert(fleet.to_owned(), done);
        Ok(())
    }

    /// `fleet`'s solve, taken and run here on the worker.
    fn run_now(&mut self, fleet: &str) -> Result<Done, OptimizeError> {
        let solve = self.take_now(fleet)?;
        Ok(Done {
            fleet: fleet.to_owned(),
            taken_after: solve.nodes() as u64 - 1,
            solved: solve.run(),
        })
    }

    /// `fleet`'s solve, taken now: once the one out comes back (applied as usual), or the
    /// one a feed holds is applied.
    fn take_now(&mut self, fleet: &str) -> Result<BackgroundSolve, OptimizeError> {
        // Before solving: a solve whose point is not stored would not be replayed.
        if let Some(fault) = self.shared.store_fault() {
            return Err(OptimizeError::StoreFailed(fault));
        }
        if self.site_waits(fleet) {
            let why = format!("site {fleet}: its last entries are not durable yet");
            return Err(OptimizeError::StoreFailed(why));
        }
        if !self.fleets.contains_key(fleet) {
            return Err(OptimizeError::Refused(format!("no fleet {fleet}")));
        }
        if let Some(done) = self.solving.held.remove(fleet) {
            self.apply_solve(done).map_err(OptimizeError::StoreFailed)?;
        }
        while self.solving.out.contains_key(fleet) {
            let done = self
                .solving
                .done
                .recv()
                .map_err(|_| OptimizeError::Stopped)?;
            if self.site_waits(&done.fleet) {
                self.solving.deferred.push(done);
                continue;
            }
            self.apply_solve(done).map_err(OptimizeError::StoreFailed)?;
        }
        let map = self.fleets.get_mut(fleet).expect("checked above");
        map.take_solve_now()
            .ok_or_else(|| OptimizeError::Refused(format!("a solve of {fleet} is held")))
    }

    /// Applies a solve run for a request; its report, or why not.
    fn applied(&mut self, done: Done) -> Result<serde_json::Value, OptimizeError> {
        let fleet = done.fleet.clone();
        match self.apply_solve(done) {
            Ok(true) => {}
            Ok(false) => {
                let why = "part of the network is not anchored yet";
                return Err(OptimizeError::Refused(why.into()));
            }
            Err(e) => return Err(OptimizeError::StoreFailed(e)),
        }
        let report = self.fleets[&fleet].last_optimization();
        Ok(serde_json::to_value(report).expect("report serializes"))
    }
}
