//! The experiment's model: the methods compared, the settings of a grid
//! and the link of each of its cells.

use twindrive_agent::direct::DirectMethod;
use twindrive_link::emulator::LinkProfile;
use twindrive_plot::palette;

/// The methods, in the order of the tables.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    Direct(DirectMethod),
    Decoupled,
}

impl Method {
    pub fn name(&self) -> &'static str {
        match self {
            Method::Direct(DirectMethod::HoldLast) => "direct (a) hold-last",
            Method::Direct(DirectMethod::Watchdog { .. }) => "direct (b) watchdog",
            Method::Direct(DirectMethod::MoveAndWait { .. }) => "direct (c) move-and-wait",
            Method::Decoupled => "decoupled",
        }
    }

    pub fn color(&self) -> twindrive_plot::RGBColor {
        match self {
            Method::Direct(DirectMethod::HoldLast) => palette::BAD,
            Method::Direct(DirectMethod::Watchdog { .. }) => palette::ALT,
            Method::Direct(DirectMethod::MoveAndWait { .. }) => palette::PURPLE,
            Method::Decoupled => palette::GOOD,
        }
    }
}

/// The experiment's settings, checked.
#[derive(Debug, Clone)]
pub struct Settings {
    pub latencies_s: Vec<f64>,
    pub losses: Vec<f64>,
    pub seeds: u64,
    pub bandwidth_bit_s: f64,
    pub watchdog_timeout_s: f64,
    pub move_s: f64,
    pub coverage_radius_m: f64,
    pub complete_at: f64,
    pub max_duration_s: f64,
}

impl Settings {
    /// The demo's short version: 0, 0.5 and 2 s one way at 10 % loss, one
    /// seed.
    pub fn demo() -> Self {
        Settings {
            latencies_s: vec![0.0, 0.5, 2.0],
            losses: vec![0.1],
            seeds: 1,
            bandwidth_bit_s: 256_000.0,
            watchdog_timeout_s: 0.5,
            move_s: 0.5,
            coverage_radius_m: 0.15,
            complete_at: 0.9,
            max_duration_s: 1_800.0,
        }
    }

    pub fn methods(&self) -> [Method; 4] {
        [
            Method::Direct(DirectMethod::HoldLast),
            Method::Direct(DirectMethod::Watchdog {
                timeout_s: self.watchdog_timeout_s,
            }),
            Method::Direct(DirectMethod::MoveAndWait {
                move_s: self.move_s,
            }),
            Method::Decoupled,
        ]
    }

    /// The link of one cell: the same both ways and for every method.
    pub fn link(&self, latency_s: f64, loss: f64) -> LinkProfile {
        let mut p: LinkProfile = "latency_s=0".parse().expect("a valid profile");
        p.name = format!("latency {latency_s} s, loss {loss}");
        p.latency_s = latency_s;
        // A little jitter, so messages of a stream can arrive out of order.
        p.jitter_s = 0.02 * latency_s;
        p.loss = loss;
        p.bandwidth_bit_s = Some(self.bandwidth_bit_s);
        p
    }
}
