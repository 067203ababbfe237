//! The measurements behind the claim that decoupling wins, and the case
//! study end to end, as `twindrive demo` and `twindrive experiment` run
//! them:
//!
//! - [`rehearsal`]: the mission rehearsed on the twin, the site it runs
//!   on, the score of a true path against the route;
//! - [`mission`]: a decoupled mission in one process, in virtual time;
//! - [`latency`]: direct tele-operation against decoupled operation over a
//!   grid of latencies and losses (model, runner, report);
//! - [`mismatch`]: decoupled operation as the site's kinematics depart
//!   from the twin's, per range sensor, with and without localization;
//! - [`upload`]: the plan upload against the ideal the link allows;
//! - [`fleet`]: one master, N robot processes, a zenoh router; and the
//!   master's protocol cost per robot in virtual time;
//! - [`demo`]: the case study (calibration, Table 1 and Section 6, the
//!   mission, plan, verification, decoupled operation, the latency
//!   section) and its report;
//! - [`pool`]: jobs on every core, results in the jobs' order.

pub mod demo;
pub mod fleet;
pub mod latency;
pub mod mismatch;
pub mod mission;
pub mod pool;
pub mod rehearsal;
pub mod upload;
