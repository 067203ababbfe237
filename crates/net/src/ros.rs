//! A ROS 2 robot behind the agent, over zenoh as rmw_zenoh speaks it.
//!
//! [`RosBackend`] carries a [`RosBridge`] (the I/O-free part, in
//! `twindrive-agent`) over a zenoh session to the robot's rmw_zenoh router:
//! it subscribes to the drivers' topics on rmw_zenoh key expressions (any
//! type hash, so a robot on a later distribution is heard; a hash other
//! than twindrive's is logged once), publishes the command topic with
//! rmw_zenoh's attachment, and declares liveliness tokens for its node, its
//! subscriptions and its publisher, so `ros2 node list` and `ros2 topic
//! info` on the robot see the agent. Messages that do not decode are logged
//! (rate-limited) and dropped.

use std::sync::{Arc, Mutex};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use twindrive_agent::backend::{Reading, RobotBackend};
use twindrive_agent::ros::RosBridge;
use twindrive_log::{LogHeader, WorldMap};
use twindrive_ros::rmw_zenoh::{self, Attachment, Entity, NodeId, Qos};

/// Warnings about one topic at most this often (s).
const WARN_EVERY_S: f64 = 5.0;

/// The agent's backend for a ROS 2 robot.
pub struct RosBackend {
    bridge: Arc<Mutex<RosBridge>>,
    clock: Instant,
    commands: tokio::sync::mpsc::UnboundedSender<Vec<u8>>,
    period_s: f64,
    travel_rad: f64,
    map: Option<WorldMap>,
    /// Kept alive: dropping them withdraws the agent from the ROS graph.
    _tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

fn unix_ns() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as i64)
        .unwrap_or(0)
}

impl RosBackend {
    /// Declares the agent on `network` (the robot's ROS network, which
    /// rmw_zenoh makes a zenoh one) and starts listening. `clock` is the
    /// bridge's time zero.
    pub async fn open(
        network: &crate::Network,
        bridge: RosBridge,
        clock: Instant,
        map: Option<WorldMap>,
    ) -> anyhow::Result<Self> {
        let session = network.zenoh().ok_or_else(|| {
            anyhow::anyhow!("a ROS 2 robot is reached through rmw_zenoh: it needs a zenoh network")
        })?;
        let config = bridge.config().clone();
        let zid = session.zid().to_string();
        let node = NodeId {
            domain_id: config.domain_id,
            zid: &zid,
            node_id: 0,
            namespace: &config.namespace,
            name: &config.node_name,
        };
        let mut tokens = Vec::new();
        let mut declare = async |key: String| -> anyhow::Result<()> {
            let t = session
                .liveliness()
                .declare_token(key.clone())
                .await
                .map_err(|e| anyhow::anyhow!("declaring the liveliness token {key}: {e}"))?;
            tokens.push(t);
            Ok(())
        };
        declare(rmw_zenoh::liveliness_token(&node, 0, Entity::Node)).await?;

        let bridge = Arc::new(Mutex::new(bridge));
        let subscriptions: Vec<(String, String)> = bridge
            .lock()
            .expect("not poisoned")
            .subscriptions()
            .iter()
            .map(|s| (s.topic.clone(), s.type_name.clone()))
            .collect();
        for (i, (topic, type_name)) in subscriptions.into_iter().enumerate() {
            let ours = rmw_zenoh::type_hash(&type_name).unwrap_or_default();
            declare(rmw_zenoh::liveliness_token(
                &node,
                i as u32 + 1,
                Entity::Subscription {
                    topic: &topic,
                    type_name: &type_name,
                    hash: &ours,
                    qos: Qos::DEFAULT,
                },
            ))
            .await?;
            let key = rmw_zenoh::topic_key_any_hash(config.domain_id, &topic, &type_name);
            let sub = session
                .declare_subscriber(key.clone())
                .await
                .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?;
            let bridge = bridge.clone();
            tokio::spawn(async move {
                let mut last_warning = f64::NEG_INFINITY;
                let mut warned_hash = false;
                let mut heard = false;
                while let Ok(sample) = sub.recv_async().await {
                    let now_s = clock.elapsed().as_secs_f64();
                    let hash = sample.key_expr().as_str().rsplit('/').next().unwrap_or("");
                    if !warned_hash && hash != ours {
                        warned_hash = true;
                        tracing::warn!(
                            topic = %topic,
                            theirs = hash,
                            ours = %ours,
                            "the robot's type hash differs from twindrive's (another distribution?); decoding with twindrive's definition"
                        );
                    }
                    let bytes = sample.payload().to_bytes();
                    let result = bridge
                        .lock()
                        .expect("not poisoned")
                        .on_message(i, &bytes, now_s);
                    if result.is_ok() && !heard {
                        heard = true;
                        // One line when each driver is first heard: an
                        // operator (and a test) knows the robot is up.
                        tracing::info!(topic = %topic, "first message from the robot");
                    }
                    if let Err(e) = result
                        && now_s - last_warning > WARN_EVERY_S
                    {
                        last_warning = now_s;
                        tracing::warn!(error = %e, "dropped a message that does not decode");
                    }
                }
            });
        }

        let (topic, type_name) = {
            let b = bridge.lock().expect("not poisoned");
            let (t, ty) = b.command_topic();
            (t.to_string(), ty.to_string())
        };
        let hash = rmw_zenoh::type_hash(&type_name).unwrap_or_default();
        let entity_id = bridge.lock().expect("not poisoned").subscriptions().len() as u32 + 1;
        let publisher_token = rmw_zenoh::liveliness_token(
            &node,
            entity_id,
            Entity::Publisher {
                topic: &topic,
                type_name: &type_name,
                hash: &hash,
                qos: Qos::DEFAULT,
            },
        );
        let gid = rmw_zenoh::gid(&publisher_token);
        declare(publisher_token).await?;
        let key = rmw_zenoh::topic_key(config.domain_id, &topic, &type_name, &hash);
        let publisher = session
            .declare_publisher(key.clone())
            .await
            .map_err(|e| anyhow::anyhow!("declaring the publisher on {key}: {e}"))?;
        let (commands, mut rx) = tokio::sync::mpsc::unbounded_channel::<Vec<u8>>();
        tokio::spawn(async move {
            let mut sequence_number = 0i64;
            while let Some(bytes) = rx.recv().await {
                sequence_number += 1;
                let attachment = Attachment {
                    sequence_number,
                    source_timestamp_ns: unix_ns(),
                    gid,
                }
                .encode();
                if let Err(e) = publisher.put(bytes).attachment(attachment.to_vec()).await {
                    tracing::warn!(error = %e, "publishing a wheel command");
                }
            }
        });
        let period_s = config.period_s;
        Ok(Self {
            bridge,
            clock,
            commands,
            period_s,
            travel_rad: 0.0,
            map,
            _tokens: tokens,
        })
    }

    /// Messages received per subscription, rejected, and commands sent.
    pub fn stats(&self) -> twindrive_agent::ros::BridgeStats {
        self.bridge.lock().expect("not poisoned").stats().clone()
    }
}

impl RobotBackend for RosBackend {
    fn period_s(&self) -> f64 {
        self.period_s
    }

    fn step(&mut self, decide: &mut dyn FnMut(&Reading) -> [f64; 2]) -> Option<Reading> {
        let now_s = self.clock.elapsed().as_secs_f64();
        let (reading, command) = self
            .bridge
            .lock()
            .expect("not poisoned")
            .step(now_s, decide);
        // The publishing task only goes when the runtime does.
        self.commands.send(command).ok()?;
        let w = reading.record.wheel_rad_s;
        self.travel_rad += (w[0].abs() + w[1].abs()) * self.period_s;
        Some(reading)
    }

    /// Zero on the command topic every period while no plan runs: a motor
    /// controller that holds its last command (or keeps it until its own
    /// timeout) stays stopped.
    fn hold(&mut self) -> bool {
        let now_s = self.clock.elapsed().as_secs_f64();
        let command = self.bridge.lock().expect("not poisoned").hold(now_s);
        self.commands.send(command).is_ok()
    }

    fn wheel_travel_rad(&self) -> f64 {
        self.travel_rad
    }

    fn log_header(&self) -> LogHeader {
        self.bridge.lock().expect("not poisoned").log_header()
    }

    fn map(&self) -> Option<WorldMap> {
        self.map.clone()
    }
}
