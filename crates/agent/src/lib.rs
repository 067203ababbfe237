//! Both ends of decoupled operation, without I/O: time and messages go in
//! as arguments, so the same code runs over zenoh in two processes and in
//! virtual time in one.
//!
//! - [`backend`]: the boundary to the robot (a site simulator today);
//! - [`executive`]: drives an accepted plan and decides every stop locally;
//! - [`localize`]: where the robot is on the plan's map, from its range
//!   readings, for the robot's filter;
//! - [`navigator`]: the robot's estimate (augmented EKF on encoders, any
//!   tracker and the localizer's matches);
//! - [`robot`]: the robot agent (uploads, plan gate, execution, online EKF,
//!   journal, telemetry, hand-back, log back-fill);
//! - [`master`]: the master's end (upload, supervision, telemetry, hand-backs, robot logs);
//! - [`narrate`]: what the master says while it works, for people;
//! - [`twin`]: updating the twin from a hand-back, and the continuation plan;
//! - [`direct`]: direct tele-operation over the same link, the baseline
//!   decoupled operation is measured against.

pub mod backend;
pub mod direct;
pub mod executive;
pub mod local_planner;
pub mod localize;
pub mod master;
pub mod narrate;
pub mod navigator;
pub mod operator;
pub mod refine;
pub mod robot;
pub mod ros;
pub mod store;
pub mod twin;

use twindrive_link::secure::Refusal;
use twindrive_link::upload::ChunkStore;
use twindrive_link::vtime::Endpoint;
use twindrive_link::wire::Message;

impl<B: backend::RobotBackend, S: store::RobotStore> Endpoint for robot::RobotAgent<B, S> {
    fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        robot::RobotAgent::poll_transmit(self, now_ns)
    }
    fn handle(&mut self, message: &Message, now_ns: u64) {
        robot::RobotAgent::handle(self, message, now_ns)
    }
    fn poll_timeout(&self) -> Option<u64> {
        robot::RobotAgent::poll_timeout(self)
    }
    fn refused(&mut self, refusal: &Refusal, now_ns: u64) {
        robot::RobotAgent::refused(self, refusal, now_ns)
    }
}

impl<S: ChunkStore> Endpoint for operator::Operator<S> {
    fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        operator::Operator::poll_transmit(self, now_ns)
    }
    fn handle(&mut self, message: &Message, now_ns: u64) {
        operator::Operator::handle(self, message, now_ns)
    }
    fn poll_timeout(&self) -> Option<u64> {
        operator::Operator::poll_timeout(self)
    }
    fn refused(&mut self, refusal: &Refusal, now_ns: u64) {
        operator::Operator::refused(self, refusal, now_ns)
    }
}
