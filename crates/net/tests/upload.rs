//! An upload over real zenoh sessions on loopback (two peers in one
//! process), and over the in-process bus through the same seam, with and
//! without the emulated link: the file arrives byte identical, and garbage
//! on the wire is dropped without stopping anything.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use twindrive_link::LinkEmulator;
use twindrive_link::upload::{
    MemoryStore, Receiver, ReceiverConfig, ReceiverEvent, Sender, SenderConfig,
};
use twindrive_net::{DriveStats, Emulation, MemoryBus, Network, SessionOptions, drive, up_key};

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Two zenoh peers on loopback: the robot's side listens, the master's
/// connects.
async fn zenoh_pair() -> (Network, Network) {
    let port = free_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let robot_side = Network::open(&SessionOptions {
        listen: vec![endpoint.clone()],
        ..SessionOptions::default()
    })
    .await
    .unwrap();
    let master_side = Network::open(&SessionOptions {
        connect: vec![endpoint],
        ..SessionOptions::default()
    })
    .await
    .unwrap();
    (robot_side, master_side)
}

async fn upload(
    (robot_side, master_side): (Network, Network),
    emulation: Option<Emulation>,
    garbage: bool,
) -> (Vec<u8>, Option<Vec<u8>>, DriveStats) {
    let data: Vec<u8> = (0..60_000u32).map(|k| (k * 7 % 251) as u8).collect();
    let mut sender = Sender::new(
        "rover",
        data.clone(),
        SenderConfig {
            rtt_hint_ns: 50_000_000,
            ..SenderConfig::default()
        },
    );
    let mut receiver = Receiver::new(
        "rover",
        MemoryStore::default(),
        ReceiverConfig {
            nak_interval_ns: 50_000_000,
            ..ReceiverConfig::default()
        },
    );
    if garbage {
        // Someone else's bytes on the robot's key expression.
        let mut p = master_side
            .channel(&up_key("rover"), "twindrive/nobody/down")
            .await
            .unwrap();
        tokio::spawn(async move {
            for k in 0..50u8 {
                let _ = p.send(vec![k; usize::from(k)]).await;
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
        });
    }
    let finished = Arc::new(AtomicBool::new(false));
    let mut got = None;
    let (master_peers, robot_peers) = twindrive_link::secure::memory_pair(
        &twindrive_link::secure::key_from_seed(1, 0),
        &twindrive_link::secure::key_from_seed(1, 1),
        "rover",
    );
    let mut master_link = twindrive_net::LinkEnd::master("rover", master_peers);
    let mut robot_link = twindrive_net::LinkEnd::robot("rover", robot_peers);
    let (master, robot) = tokio::join!(
        drive(
            &mut sender,
            &master_side,
            &mut master_link,
            emulation,
            Duration::from_secs(60),
            |s| {
                let f = s.is_finished();
                if f {
                    finished.store(true, Ordering::SeqCst);
                }
                f
            },
        ),
        drive(
            &mut receiver,
            &robot_side,
            &mut robot_link,
            None,
            Duration::from_secs(60),
            |r| {
                while let Some(e) = r.poll_event() {
                    if let ReceiverEvent::Completed { file, .. } = e {
                        got = Some(file);
                    }
                }
                finished.load(Ordering::SeqCst)
            },
        ),
    );
    master.unwrap();
    let robot_stats = robot.unwrap();
    master_side.close().await;
    robot_side.close().await;
    (data, got, robot_stats)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_file_crosses_zenoh_byte_identical() {
    let (data, got, stats) = upload(zenoh_pair().await, None, true).await;
    assert_eq!(got.as_deref(), Some(&data[..]));
    assert!(stats.refused > 0, "{stats:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_file_crosses_zenoh_through_an_emulated_lossy_link() {
    let profile: twindrive_link::LinkProfile =
        "latency_s=0.02,jitter_s=0.005,loss=0.2,bandwidth_bit_s=4e6"
            .parse()
            .unwrap();
    let emulation = Emulation {
        outgoing: LinkEmulator::new(profile.clone(), 5, 0),
        incoming: LinkEmulator::new(profile, 5, 1),
    };
    let (data, got, _) = upload(zenoh_pair().await, Some(emulation), false).await;
    assert_eq!(got.as_deref(), Some(&data[..]));
}

/// The same drivers on the in-process bus, no socket: through a lossy
/// emulated link and garbage on the robot's key, the file arrives whole.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_file_crosses_the_in_process_bus_as_it_crosses_zenoh() {
    let profile: twindrive_link::LinkProfile =
        "latency_s=0.02,jitter_s=0.005,loss=0.2,bandwidth_bit_s=4e6"
            .parse()
            .unwrap();
    let emulation = Emulation {
        outgoing: LinkEmulator::new(profile.clone(), 9, 0),
        incoming: LinkEmulator::new(profile, 9, 1),
    };
    let bus = MemoryBus::default();
    let (data, got, stats) = upload((bus.network(), bus.network()), Some(emulation), true).await;
    assert_eq!(got.as_deref(), Some(&data[..]));
    assert!(stats.refused > 0, "{stats:?}");
    assert!(stats.messages_received > 0, "{stats:?}");
}
