//! The fleet configuration files in `deploy/` load, and a robot and a
//! master configured by them (client mode) reach each other through a
//! router configured by `deploy/router.json5`, on a free loopback port.

use std::path::PathBuf;
use std::time::Duration;

use twindrive_link::upload::{
    MemoryStore, Receiver, ReceiverConfig, ReceiverEvent, Sender, SenderConfig,
};
use twindrive_net::{SessionOptions, down_key, drive, open_session, up_key};

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
        mode: None,
    };
    let router = open_session(&options("router.json5", true)).await.unwrap();
    let robot = open_session(&options("robot.json5", false)).await.unwrap();
    let master = open_session(&options("master.json5", false)).await.unwrap();
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
    let (up, down) = (up_key("rover-1"), down_key("rover-1"));
    let mut got = None;
    let (m, _) = tokio::join!(
        drive(
            &mut sender,
            &master,
            "rover-1",
            &up,
            &down,
            None,
            Duration::from_secs(30),
            |s| s.is_finished(),
        ),
        drive(
            &mut receiver,
            &robot,
            "rover-1",
            &down,
            &up,
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
        s.close().await.unwrap();
    }
}
