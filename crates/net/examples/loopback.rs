//! Two real processes on loopback with zenoh in between and no emulation:
//! plan-upload throughput (MB/s) and the round trip of a small message
//! (ms), the protocol's own costs on a perfect link.
//!
//! `cargo run --release -p twindrive-net --example loopback -- [--smoke] [--mb N] [--pings N]`
//!
//! The example starts itself again as the robot (`--role robot`), uploads N
//! MB of random bytes to it with the chunked upload, then sends pings one
//! at a time and times the pongs. The child is killed by its process id at
//! the end.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use rand::{RngExt, SeedableRng};
use twindrive_link::secure::{Peers, key_from_seed, memory_pair};
use twindrive_link::upload::{MemoryStore, Receiver, ReceiverConfig, Sender, SenderConfig};
use twindrive_link::vtime::Endpoint;
use twindrive_link::wire::{Body, Message, Stamper};
use twindrive_net::{LinkEnd, Network, SessionOptions, drive};

const ROBOT: &str = "bench";

/// Both ends' sealing (every message is sealed, as between master and
/// robot), from fixed keys: the master's and the robot's.
fn ends() -> (Peers, Peers) {
    memory_pair(&key_from_seed(1, 0), &key_from_seed(1, 1), ROBOT)
}

/// The robot's side: assembles uploads and answers pings.
struct RobotSide {
    receiver: Receiver<MemoryStore>,
    stamper: Stamper,
    pongs: Vec<u64>,
}

impl Endpoint for RobotSide {
    fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        if let Some(nonce) = self.pongs.pop() {
            return Some(self.stamper.stamp(Body::Pong { nonce }, now_ns));
        }
        self.receiver.poll_transmit(now_ns)
    }
    fn handle(&mut self, message: &Message, now_ns: u64) {
        match message.body {
            Body::Ping { nonce } => self.pongs.push(nonce),
            _ => self.receiver.handle(message, now_ns),
        }
    }
    fn poll_timeout(&self) -> Option<u64> {
        if self.pongs.is_empty() {
            self.receiver.poll_timeout()
        } else {
            Some(0)
        }
    }
}

/// Pings one at a time, recording each round trip.
struct Pinger {
    stamper: Stamper,
    left: usize,
    waiting: Option<(u64, u64)>,
    rtt_ns: Vec<u64>,
}

impl Endpoint for Pinger {
    fn poll_transmit(&mut self, now_ns: u64) -> Option<Message> {
        // A ping lost on the way is sent again after a second.
        if let Some((_, sent)) = self.waiting
            && now_ns < sent + 1_000_000_000
        {
            return None;
        }
        if self.left == 0 {
            return None;
        }
        let nonce = self.left as u64;
        self.waiting = Some((nonce, now_ns));
        Some(self.stamper.stamp(Body::Ping { nonce }, now_ns))
    }
    fn handle(&mut self, message: &Message, now_ns: u64) {
        if let (Body::Pong { nonce }, Some((want, sent))) = (&message.body, self.waiting)
            && *nonce == want
        {
            self.rtt_ns.push(now_ns - sent);
            self.waiting = None;
            self.left -= 1;
        }
    }
    fn poll_timeout(&self) -> Option<u64> {
        Some(self.waiting.map_or(0, |(_, sent)| sent + 1_000_000_000))
    }
}

fn arg<T: std::str::FromStr>(args: &[String], name: &str) -> Option<T> {
    args.iter()
        .position(|a| a == name)
        .and_then(|k| args.get(k + 1))
        .and_then(|v| v.parse().ok())
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("a runtime")
}

fn robot(port: u16) -> anyhow::Result<()> {
    runtime().block_on(async {
        let network = Network::open(&SessionOptions {
            listen: vec![format!("tcp/127.0.0.1:{port}")],
            ..SessionOptions::default()
        })
        .await?;
        let mut side = RobotSide {
            receiver: Receiver::new(
                ROBOT,
                MemoryStore::default(),
                ReceiverConfig {
                    max_file_bytes: 1 << 31,
                    nak_interval_ns: 20_000_000,
                },
            ),
            stamper: Stamper::new(ROBOT),
            pongs: Vec::new(),
        };
        // Until the parent kills it (or a bounded while).
        let mut link = LinkEnd::robot(ROBOT, ends().1);
        let _ = drive(
            &mut side,
            &network,
            &mut link,
            None,
            Duration::from_secs(300),
            |_| false,
        )
        .await;
        Ok(())
    })
}

/// Kills the child by its process id when dropped.
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--role") {
        return robot(arg(&args, "--port").expect("--port"));
    }
    let smoke = args.iter().any(|a| a == "--smoke");
    let mb: f64 = arg(&args, "--mb").unwrap_or(if smoke { 1.0 } else { 32.0 });
    let pings: usize = arg(&args, "--pings").unwrap_or(if smoke { 20 } else { 500 });
    let port = std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port();
    let _child = Killed(
        Command::new(std::env::current_exe()?)
            .args(["--role", "robot", "--port", &port.to_string()])
            .stdout(Stdio::null())
            .spawn()?,
    );
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let file: Vec<u8> = (0..(mb * 1e6) as usize).map(|_| rng.random()).collect();
    runtime().block_on(async {
        let network = Network::open(&SessionOptions {
            connect: vec![format!("tcp/127.0.0.1:{port}")],
            ..SessionOptions::default()
        })
        .await?;
        // Let the peers find each other before the clock starts.
        tokio::time::sleep(Duration::from_millis(500)).await;
        let mut sender = Sender::new(
            ROBOT,
            file.clone(),
            SenderConfig {
                chunk_bytes: 16 * 1024,
                rtt_hint_ns: 5_000_000,
                ..SenderConfig::default()
            },
        );
        let mut link = LinkEnd::master(ROBOT, ends().0);
        let start = Instant::now();
        drive(
            &mut sender,
            &network,
            &mut link,
            None,
            Duration::from_secs(240),
            |s| s.is_finished(),
        )
        .await?;
        let s = start.elapsed().as_secs_f64();
        println!(
            "upload over loopback zenoh, two processes: {:.1} MB in {s:.2} s = {:.1} MB/s ({} chunks of 16 KiB, {} resent)",
            mb,
            mb / s,
            sender.stats.chunks,
            sender.stats.chunks_resent
        );
        let mut pinger = Pinger {
            stamper: Stamper::new(ROBOT),
            left: pings,
            waiting: None,
            rtt_ns: Vec::new(),
        };
        drive(
            &mut pinger,
            &network,
            &mut link,
            None,
            Duration::from_secs(120),
            |p| p.left == 0,
        )
        .await?;
        let mut rtt = pinger.rtt_ns.clone();
        rtt.sort_unstable();
        let ms = |q: f64| rtt[((rtt.len() - 1) as f64 * q) as usize] as f64 * 1e-6;
        println!(
            "round trip of a message and its answer over loopback zenoh: median {:.3} ms, p95 {:.3} ms, max {:.3} ms ({} pings)",
            ms(0.5),
            ms(0.95),
            ms(1.0),
            rtt.len()
        );
        anyhow::Ok(())
    })
}
