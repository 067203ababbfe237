//! The fleet configuration files in `deploy/` load, and a robot and a
//! master configured by them (client mode) reach each other through a
//! router configured by `deploy/router.json5`, on a free loopback port.

use std::path::PathBuf;
use std::time::Duration;

use twindrive_link::upload::{
    MemoryStore, Receiver, ReceiverConfig, ReceiverEvent, Sender, SenderConfig,
};
use twindrive_net::{Network, SessionOptions, drive};

fn deploy(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../deploy")
        .join(name)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn robot_and_master_configured_by_deploy_meet_through_its_router() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let options = |file: &str, listen: bool| SessionOptions {
        listen: if listen {
            vec![endpoint.clone()]
        } else {
            vec![]
        },
        connect: if listen {
            vec![]
        } else {
            vec![endpoint.clone()]
        },
        config_file: Some(deploy(file)),
        ..SessionOptions::default()
    };
    let router = Network::open(&options("router.json5", true)).await.unwrap();
    let robot = Network::open(&options("robot.json5", false)).await.unwrap();
    let master = Network::open(&options("master.json5", false))
        .await
        .unwrap();
    let data: Vec<u8> = (0..20_000u32).map(|k| (k % 241) as u8).collect();
    let mut sender = Sender::new(
        "rover-1",
        data.clone(),
        SenderConfig {
            rtt_hint_ns: 50_000_000,
            ..SenderConfig::default()
        },
    );
    let mut receiver = Receiver::new(
        "rover-1",
        MemoryStore::default(),
        ReceiverConfig {
            nak_interval_ns: 50_000_000,
            ..ReceiverConfig::default()
        },
    );
    let (master_peers, robot_peers) = twindrive_link::secure::memory_pair(
        &twindrive_link::secure::key_from_seed(1, 0),
        &twindrive_link::secure::key_from_seed(1, 1),
        "rover-1",
    );
    let mut master_link = twindrive_net::LinkEnd::master("rover-1", master_peers);
    let mut robot_link = twindrive_net::LinkEnd::robot("rover-1", robot_peers);
    let mut got = None;
    let (m, _) = tokio::join!(
        drive(
            &mut sender,
            &master,
            &mut master_link,
            None,
            Duration::from_secs(30),
            |s| s.is_finished(),
        ),
        drive(
            &mut receiver,
            &robot,
            &mut robot_link,
            None,
            Duration::from_secs(30),
            |r| {
                while let Some(e) = r.poll_event() {
                    if let ReceiverEvent::Completed { file, .. } = e {
                        got = Some(file);
                    }
                }
                got.is_some()
            },
        ),
    );
    m.unwrap();
    assert_eq!(got.as_deref(), Some(&data[..]));
    for s in [master, robot, router] {
        s.close().await;
    }
}

/// `deploy/tls/` (what `twindrive certs` writes) loads as zenoh
/// configurations with this build's transports (TLS among them).
#[test]
fn the_tls_examples_load() {
    for name in ["router.json5", "master.json5", "r1.json5"] {
        let path = deploy(&format!("tls/{name}"));
        if let Err(e) = zenoh::Config::from_file(&path) {
            panic!("{}: {e}", path.display());
        }
    }
}
