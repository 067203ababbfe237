//! The transport seam: what a link needs of the network under it, and
//! nothing more.
//!
//! A link sends sealed payloads on one key expression and receives them on
//! another (`twindrive/ID/up`, `twindrive/ID/down`). [`Transport`] is that
//! and only that: open a [`Channel`] for a pair of keys, close. The
//! processes (`twindrive-ops`, `twindrive-console`) and [`crate::drive`]
//! hold a [`Network`], a cheap handle on one transport shared by every
//! robot's link, and never a zenoh type. Two transports stand behind it:
//! zenoh ([`Network::open`], a session opened as [`SessionOptions`] say,
//! the one place where flags and a configuration file become endpoints)
//! and an in-process bus ([`MemoryBus`]) on which tests run the same
//! drivers with no socket.

use std::any::Any;
use std::collections::HashMap;
use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex};

use crate::session::{SessionOptions, open_session};

/// A boxed future, as the seam's traits return them (they are used as
/// trait objects).
pub type BoxFuture<'a, T> = Pin<Box<dyn Future<Output = T> + Send + 'a>>;

/// A network links run over.
pub trait Transport: Send + Sync + 'static {
    /// A channel that sends on `tx_key` and receives what is put on
    /// `rx_key`.
    fn channel<'a>(
        &'a self,
        tx_key: &'a str,
        rx_key: &'a str,
    ) -> BoxFuture<'a, anyhow::Result<Box<dyn Channel>>>;
    /// Closes the network (every channel on it ends).
    fn close(&self) -> BoxFuture<'_, ()>;
    /// The transport itself, for the edge that needs its own kind (a ROS 2
    /// robot is reached through rmw_zenoh, so only over zenoh).
    fn as_any(&self) -> &dyn Any;
}

/// One link's way in and out.
pub trait Channel: Send {
    /// Whether anyone listens on the send key now.
    fn listened(&mut self) -> BoxFuture<'_, anyhow::Result<bool>>;
    /// Puts one payload on the send key.
    fn send(&mut self, bytes: Vec<u8>) -> BoxFuture<'_, anyhow::Result<()>>;
    /// The next payload put on the receive key. Cancel-safe: a receive
    /// given up (a `select!` that woke on a timer) loses nothing.
    fn recv(&mut self) -> BoxFuture<'_, anyhow::Result<Vec<u8>>>;
}

/// A handle on one transport, shared by every link on it (clones are the
/// same network).
#[derive(Clone)]
pub struct Network {
    transport: Arc<dyn Transport>,
}

impl std::fmt::Debug for Network {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Network")
    }
}

impl Network {
    /// Zenoh, opened as `options` say (bounded, see
    /// [`crate::session`]).
    pub async fn open(options: &SessionOptions) -> anyhow::Result<Self> {
        let session = open_session(options).await?;
        Ok(Self::on(Zenoh { session }))
    }

    /// A network on `transport`.
    pub fn on(transport: impl Transport) -> Self {
        Self {
            transport: Arc::new(transport),
        }
    }

    /// A channel that sends on `tx_key` and receives on `rx_key`.
    pub async fn channel(&self, tx_key: &str, rx_key: &str) -> anyhow::Result<Box<dyn Channel>> {
        self.transport.channel(tx_key, rx_key).await
    }

    /// Closes the network.
    pub async fn close(&self) {
        self.transport.close().await;
    }

    /// The zenoh session under this network, if it is zenoh.
    pub(crate) fn zenoh(&self) -> Option<&zenoh::Session> {
        self.transport
            .as_any()
            .downcast_ref::<Zenoh>()
            .map(|z| &z.session)
    }
}

/// Zenoh: a publisher and a subscriber per channel on one session.
struct Zenoh {
    session: zenoh::Session,
}

impl Transport for Zenoh {
    fn channel<'a>(
        &'a self,
        tx_key: &'a str,
        rx_key: &'a str,
    ) -> BoxFuture<'a, anyhow::Result<Box<dyn Channel>>> {
        Box::pin(async move {
            let publisher = self
                .session
                .declare_publisher(tx_key.to_string())
                .await
                .map_err(|e| anyhow::anyhow!("declaring the publisher on {tx_key}: {e}"))?;
            let subscriber = self
                .session
                .declare_subscriber(rx_key.to_string())
                .await
                .map_err(|e| anyhow::anyhow!("declaring the subscriber on {rx_key}: {e}"))?;
            Ok(Box::new(ZenohChannel {
                publisher,
                subscriber,
                tx_key: tx_key.to_string(),
                rx_key: rx_key.to_string(),
            }) as Box<dyn Channel>)
        })
    }

    fn close(&self) -> BoxFuture<'_, ()> {
        Box::pin(async move {
            let _ = self.session.close().await;
        })
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

struct ZenohChannel {
    publisher: zenoh::pubsub::Publisher<'static>,
    subscriber:
        zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    tx_key: String,
    rx_key: String,
}

impl Channel for ZenohChannel {
    fn listened(&mut self) -> BoxFuture<'_, anyhow::Result<bool>> {
        Box::pin(async move {
            self.publisher
                .matching_status()
                .await
                .map(|m| m.matching())
                .map_err(|e| {
                    anyhow::anyhow!("the publisher's matching status on {}: {e}", self.tx_key)
                })
        })
    }

    fn send(&mut self, bytes: Vec<u8>) -> BoxFuture<'_, anyhow::Result<()>> {
        Box::pin(async move {
            self.publisher
                .put(bytes)
                .await
                .map_err(|e| anyhow::anyhow!("publishing on {}: {e}", self.tx_key))
        })
    }

    fn recv(&mut self) -> BoxFuture<'_, anyhow::Result<Vec<u8>>> {
        Box::pin(async move {
            let sample =
                self.subscriber.recv_async().await.map_err(|e| {
                    anyhow::anyhow!("the subscriber on {} closed: {e}", self.rx_key)
                })?;
            Ok(sample.payload().to_bytes().into_owned())
        })
    }
}

/// An in-process bus: every [`Network`] made from one bus (or its clones)
/// reaches every other, as peers on one zenoh network would; what is put
/// on a key goes to every channel receiving on it at that moment, and is
/// lost when none is (as zenoh's puts are).
#[derive(Clone, Default)]
pub struct MemoryBus {
    subscribers: Arc<Mutex<Subscribers>>,
}

/// The channels receiving on each key.
type Subscribers = HashMap<String, Vec<tokio::sync::mpsc::UnboundedSender<Vec<u8>>>>;

impl MemoryBus {
    /// A network on this bus.
    pub fn network(&self) -> Network {
        Network::on(self.clone())
    }

    /// Puts `bytes` on `key` for every channel receiving there now (for a
    /// test standing in for someone else on the network); how many got it.
    pub fn put(&self, key: &str, bytes: Vec<u8>) -> usize {
        let mut subscribers = self.subscribers.lock().unwrap_or_else(|e| e.into_inner());
        let Some(list) = subscribers.get_mut(key) else {
            return 0;
        };
        list.retain(|s| !s.is_closed());
        for s in list.iter() {
            let _ = s.send(bytes.clone());
        }
        list.len()
    }

    fn listened(&self, key: &str) -> bool {
        let subscribers = self.subscribers.lock().unwrap_or_else(|e| e.into_inner());
        subscribers
            .get(key)
            .is_some_and(|l| l.iter().any(|s| !s.is_closed()))
    }
}

impl Transport for MemoryBus {
    fn channel<'a>(
        &'a self,
        tx_key: &'a str,
        rx_key: &'a str,
    ) -> BoxFuture<'a, anyhow::Result<Box<dyn Channel>>> {
        let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
        self.subscribers
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .entry(rx_key.to_string())
            .or_default()
            .push(tx);
        let channel = MemoryChannel {
            bus: self.clone(),
            tx_key: tx_key.to_string(),
            incoming: rx,
        };
        Box::pin(async move { Ok(Box::new(channel) as Box<dyn Channel>) })
    }

    fn close(&self) -> BoxFuture<'_, ()> {
        Box::pin(async {})
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}

struct MemoryChannel {
    bus: MemoryBus,
    tx_key: String,
    incoming: tokio::sync::mpsc::UnboundedReceiver<Vec<u8>>,
}

impl Channel for MemoryChannel {
    fn listened(&mut self) -> BoxFuture<'_, anyhow::Result<bool>> {
        let listened = self.bus.listened(&self.tx_key);
        Box::pin(async move { Ok(listened) })
    }

    fn send(&mut self, bytes: Vec<u8>) -> BoxFuture<'_, anyhow::Result<()>> {
        self.bus.put(&self.tx_key, bytes);
        Box::pin(async { Ok(()) })
    }

    fn recv(&mut self) -> BoxFuture<'_, anyhow::Result<Vec<u8>>> {
        Box::pin(async move {
            self.incoming
                .recv()
                .await
                .ok_or_else(|| anyhow::anyhow!("the bus closed"))
        })
    }
}
