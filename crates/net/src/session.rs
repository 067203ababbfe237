//! Opening a zenoh session: the one place where flags and a zenoh
//! configuration file become a session's mode and endpoints.
//!
//! A configuration file decides what it says; `--listen`, `--connect` and
//! a process's mode replace the file's values only when given. Certificate
//! and key paths in the file's `transport/link/tls` section are taken
//! relative to the file, so a fleet's configurations (`twindrive certs`)
//! keep working wherever their directory is copied. Opening is bounded:
//! an endpoint that cannot be reached, or a handshake that never
//! completes, ends in an error that names the endpoints and says why, never
//! in a process that waits without a word.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::tls_check::{self, Finding, TlsIdentity};

/// How long opening a session may take before it is an error: a TLS
/// handshake with a router that never answers (a plain TCP client on a TLS
/// port) would otherwise hang.
pub const OPEN_TIMEOUT: Duration = Duration::from_secs(15);

/// How long a probe of an endpoint that would not take this process may
/// take ([`tls_check::probe`]).
const PROBE_TIME: Duration = Duration::from_secs(5);

/// While a peer waits for its endpoints, they are probed after this long
/// without a connection, and again as often.
const PROBE_EVERY: Duration = Duration::from_secs(2);

/// The TLS settings that name files (zenoh's `transport/link/tls`).
const TLS_FILES: [&str; 5] = [
    "root_ca_certificate",
    "listen_certificate",
    "listen_private_key",
    "connect_certificate",
    "connect_private_key",
];

/// How to open a session.
#[derive(Debug, Clone, Default)]
pub struct SessionOptions {
    /// Endpoints to listen on (`tcp/127.0.0.1:7447`); when empty, the
    /// configuration file's (none without a file).
    pub listen: Vec<String>,
    /// Endpoints to connect to; when empty, the configuration file's.
    pub connect: Vec<String>,
    /// A zenoh JSON5 configuration file. Without one: peer mode, multicast
    /// scouting off.
    pub config_file: Option<PathBuf>,
    /// `peer`, `client` (through a router) or `router`; when `None`, the
    /// file's (peer without a file).
    pub mode: Option<String>,
    /// How long to keep trying while nothing answers at the endpoints to
    /// connect to (zero: one try).
    pub patience: Duration,
}

/// Why a session did not open.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SessionError {
    /// None of the endpoints to connect to answered (nothing listens
    /// there yet, the network is down): worth trying again.
    Unreachable(String),
    /// Anything else (a port already in use, a configuration or a
    /// certificate zenoh refuses, a handshake that never completed):
    /// trying again would fail the same way.
    Failed(String),
}

impl std::fmt::Display for SessionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Unreachable(m) | Self::Failed(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for SessionError {}

impl SessionOptions {
    /// The endpoints these options listen on (`"listen"`) or connect to
    /// (`"connect"`), flags and configuration file together, as a session
    /// opened with them would.
    pub fn endpoints(&self, which: &str) -> anyhow::Result<Vec<String>> {
        Ok(endpoints(&self.config()?, which))
    }

    /// The zenoh configuration these options make.
    pub(crate) fn config(&self) -> anyhow::Result<zenoh::Config> {
        let mut config = match &self.config_file {
            Some(path) => load_config(path)?,
            None => {
                let mut c = zenoh::Config::default();
                set(&mut c, "mode", "\"peer\"")?;
                set(&mut c, "scouting/multicast/enabled", "false")?;
                c
            }
        };
        if let Some(mode) = &self.mode {
            set(&mut config, "mode", &format!("{mode:?}"))?;
        }
        if !self.listen.is_empty() {
            set(&mut config, "listen/endpoints", &json_list(&self.listen))?;
        }
        if !self.connect.is_empty() {
            set(&mut config, "connect/endpoints", &json_list(&self.connect))?;
        }
        Ok(config)
    }
}

/// Whether `session` reaches a router or another peer.
async fn connected(session: &zenoh::Session) -> bool {
    let info = session.info();
    info.routers_zid().await.next().is_some() || info.peers_zid().await.next().is_some()
}

/// `config`'s mode (`peer` when it says none).
fn mode_of(config: &zenoh::Config) -> String {
    config
        .get_json("mode")
        .ok()
        .and_then(|m| serde_json::from_str::<String>(&m).ok())
        .unwrap_or_else(|| "peer".into())
}

/// The endpoints `config` listens on (`"listen"`) or connects to
/// (`"connect"`) in its mode.
pub(crate) fn endpoints(config: &zenoh::Config, which: &str) -> Vec<String> {
    let mode = mode_of(config);
    let Ok(json) = config.get_json(&format!("{which}/endpoints")) else {
        return Vec::new();
    };
    match serde_json::from_str::<serde_json::Value>(&json) {
        Ok(serde_json::Value::Array(items)) => strings(&items),
        // Endpoints by mode: `{ router: [...], peer: [...] }`.
        Ok(serde_json::Value::Object(by_mode)) => by_mode
            .get(&mode)
            .and_then(|v| v.as_array())
            .map(|items| strings(items))
            .unwrap_or_default(),
        _ => Vec::new(),
    }
}

fn strings(items: &[serde_json::Value]) -> Vec<String> {
    items
        .iter()
        .filter_map(|v| v.as_str().map(str::to_string))
        .collect()
}

/// Opens a zenoh session as `options` say. Each try is bounded by
/// [`OPEN_TIMEOUT`]; while nothing answers at the endpoints to connect to
/// (a router not up yet, a network still coming up) it tries again every
/// second for up to `options.patience`, and any other failure (a port in
/// use, a refused configuration) ends it at once. An endpoint whose TLS
/// refuses this process (no certificate, another CA's, plain TCP on a TLS
/// port) ends it too, as soon as a probe of the endpoint
/// ([`tls_check::probe`]) finds out why: zenoh only says it could not
/// connect. A robot that boots before its link does not give up at the
/// first try, and one that can never connect says so and stops.
pub(crate) async fn open_session(options: &SessionOptions) -> anyhow::Result<zenoh::Session> {
    let started = Instant::now();
    let mut said = false;
    loop {
        let config = options.config()?;
        let probe = Probe::of(&config);
        // A peer opens without waiting for the endpoints it connects to
        // (zenoh goes on trying in the background): wait here, within the
        // patience, until one of them is connected.
        let peer_connecting = endpoints(&config, "connect");
        let peer_connecting =
            (mode_of(&config) == "peer" && !peer_connecting.is_empty()).then_some(peer_connecting);
        match open_config(config, &probe).await {
            Ok(s) => {
                if let Some(connect) = peer_connecting {
                    let limit = options.patience.max(OPEN_TIMEOUT);
                    let waiting = Instant::now();
                    let mut probing: Option<tokio::task::JoinHandle<Option<String>>> = None;
                    let mut probed_at: Option<Instant> = None;
                    while !connected(&s).await {
                        if started.elapsed() > limit {
                            let _ = s.close().await;
                            anyhow::bail!(
                                "connecting to {}: connected to nothing after {:.0} s; is the other process (or the router) running and listening there, and does the endpoint's protocol (tcp/, tls/, quic/) match its?",
                                connect.join(", "),
                                started.elapsed().as_secs_f64()
                            );
                        }
                        // zenoh keeps trying in the background and says
                        // nothing of a TLS refusal: ask the endpoints.
                        match probing.take() {
                            Some(h) if h.is_finished() => {
                                if let Some(why) = h.await.ok().flatten() {
                                    let _ = s.close().await;
                                    anyhow::bail!(why);
                                }
                            }
                            Some(h) => probing = Some(h),
                            None if waiting.elapsed() >= PROBE_EVERY
                                && probed_at.is_none_or(|t| t.elapsed() >= PROBE_EVERY) =>
                            {
                                let probe = probe.clone();
                                probing =
                                    Some(tokio::task::spawn_blocking(move || probe.refusal()));
                                probed_at = Some(Instant::now());
                            }
                            None => {}
                        }
                        tokio::time::sleep(Duration::from_millis(100)).await;
                    }
                }
                if said {
                    tracing::warn!("connected after {:.0} s", started.elapsed().as_secs_f64());
                }
                return Ok(s);
            }
            Err(SessionError::Unreachable(e)) if started.elapsed() < options.patience => {
                if !said {
                    tracing::warn!(
                        "{e}; trying again every second for up to {:.0} s",
                        options.patience.as_secs_f64()
                    );
                    said = true;
                }
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
            Err(SessionError::Unreachable(e)) if said => {
                anyhow::bail!(
                    "{e}; gave up after {:.0} s",
                    started.elapsed().as_secs_f64()
                );
            }
            Err(e) => return Err(e.into()),
        }
    }
}

/// What a probe of a configuration's endpoints needs: the endpoints to
/// connect to and the TLS files it names.
#[derive(Debug, Clone)]
struct Probe {
    connect: Vec<String>,
    /// `None`: the configuration holds certificates in itself (base64),
    /// which a probe does not read.
    identity: Option<TlsIdentity>,
}

impl Probe {
    fn of(config: &zenoh::Config) -> Self {
        Self {
            connect: endpoints(config, "connect"),
            identity: tls_identity(config),
        }
    }

    /// Why the first endpoint that refuses this process does (the whole
    /// message), if a probe finds one. Blocking: at most [`PROBE_TIME`]
    /// an endpoint.
    fn refusal(&self) -> Option<String> {
        let identity = self.identity.as_ref()?;
        self.connect
            .iter()
            .find_map(|e| match tls_check::probe(e, identity, PROBE_TIME) {
                Finding::Refused(r) => Some(r.message(e)),
                Finding::NotListening(_) | Finding::NothingFound => None,
            })
    }

    async fn refusal_async(&self) -> Option<String> {
        if self.connect.is_empty() {
            return None;
        }
        let probe = self.clone();
        tokio::task::spawn_blocking(move || probe.refusal())
            .await
            .ok()
            .flatten()
    }
}

/// The TLS files `config` names (paths as [`load_config`] made them), as
/// zenoh reads them: a client certificate only with `enable_mtls`, the
/// router's name checked unless `verify_name_on_connect` is false. `None`
/// when it holds certificates or keys in itself (`*_base64`).
fn tls_identity(config: &zenoh::Config) -> Option<TlsIdentity> {
    let get = |key: &str| {
        config
            .get_json(&format!("transport/link/tls/{key}"))
            .ok()
            .and_then(|v| serde_json::from_str::<serde_json::Value>(&v).ok())
            .filter(|v| !v.is_null())
    };
    let inline = [
        "root_ca_certificate_base64",
        "connect_certificate_base64",
        "connect_private_key_base64",
    ];
    if inline.iter().any(|k| get(k).is_some()) {
        return None;
    }
    let path = |key: &str| get(key).and_then(|v| v.as_str().map(PathBuf::from));
    let flag = |key: &str, default: bool| get(key).and_then(|v| v.as_bool()).unwrap_or(default);
    Some(TlsIdentity {
        root_ca: path("root_ca_certificate"),
        certificate: if flag("enable_mtls", false) {
            path("connect_certificate").zip(path("connect_private_key"))
        } else {
            None
        },
        verify_name: flag("verify_name_on_connect", true),
    })
}

async fn open_config(config: zenoh::Config, probe: &Probe) -> Result<zenoh::Session, SessionError> {
    let listen = endpoints(&config, "listen");
    let connect = endpoints(&config, "connect");
    let what = match (listen.is_empty(), connect.is_empty()) {
        (true, true) => "a zenoh session".to_string(),
        (false, true) => format!("listening on {}", listen.join(", ")),
        (true, false) => format!("connecting to {}", connect.join(", ")),
        (false, false) => format!(
            "listening on {}, connecting to {}",
            listen.join(", "),
            connect.join(", ")
        ),
    };
    match tokio::time::timeout(OPEN_TIMEOUT, zenoh::open(config)).await {
        Ok(Ok(session)) => Ok(session),
        Ok(Err(e)) => {
            let why = plain_error(&e.to_string());
            if why.contains("Unable to connect") {
                // Something may listen there and refuse this process's TLS.
                if let Some(refused) = probe.refusal_async().await {
                    return Err(SessionError::Failed(refused));
                }
                Err(SessionError::Unreachable(format!(
                    "{what}: nothing answered ({why}); is the router (or the other process) running and listening there, and does the endpoint's protocol (tcp/, tls/, quic/) match its?"
                )))
            } else if why.contains("listener") || why.contains("in use") {
                Err(SessionError::Failed(format!(
                    "{what}: cannot listen ({why}); choose another endpoint with --listen, or stop what holds it"
                )))
            } else {
                Err(SessionError::Failed(format!("{what}: {why}")))
            }
        }
        Err(_) => match probe.refusal_async().await {
            Some(refused) => Err(SessionError::Failed(refused)),
            None => Err(SessionError::Failed(format!(
                "{what}: no session after {} s (a TLS endpoint reached over plain TCP, or a router that refuses this client's certificate, never completes the handshake)",
                OPEN_TIMEOUT.as_secs()
            ))),
        },
    }
}

/// A zenoh configuration file, its TLS file paths taken relative to it.
fn load_config(path: &Path) -> anyhow::Result<zenoh::Config> {
    let text =
        std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let mut config = zenoh::Config::from_json5(&text).map_err(|e| {
        anyhow::anyhow!(
            "{}: not a zenoh configuration: {}",
            path.display(),
            plain_error(&e.to_string())
        )
    })?;
    let dir = path.parent().unwrap_or(Path::new("."));
    for name in TLS_FILES {
        let key = format!("transport/link/tls/{name}");
        let Some(file) = config
            .get_json(&key)
            .ok()
            .and_then(|v| serde_json::from_str::<Option<String>>(&v).ok())
            .flatten()
        else {
            continue;
        };
        let resolved = dir.join(&file);
        if !resolved.is_file() {
            anyhow::bail!(
                "{}: {key} names {} ({}), which is not a file",
                path.display(),
                file,
                resolved.display()
            );
        }
        let value = serde_json::to_string(&resolved.display().to_string())?;
        set(&mut config, &key, &value)?;
    }
    Ok(config)
}

fn set(config: &mut zenoh::Config, key: &str, value: &str) -> anyhow::Result<()> {
    config.insert_json5(key, value).map_err(|e| {
        anyhow::anyhow!(
            "zenoh configuration `{key}` = {value}: {}",
            plain_error(&e.to_string())
        )
    })
}

fn json_list(items: &[String]) -> String {
    let quoted: Vec<String> = items.iter().map(|e| format!("{e:?}")).collect();
    format!("[{}]", quoted.join(","))
}

/// A message fit for a user: without terminal colour codes and without the
/// Rust source locations zenoh's errors carry (` at /path/file.rs:12.`),
/// its ` - Caused by ` chains joined with `: `.
pub fn plain_error(text: &str) -> String {
    let mut plain = String::with_capacity(text.len());
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            // An escape sequence: `ESC [ ... letter`.
            if chars.peek() == Some(&'[') {
                chars.next();
                for d in chars.by_ref() {
                    if d.is_ascii_alphabetic() {
                        break;
                    }
                }
            }
            continue;
        }
        plain.push(c);
    }
    let mut out = String::with_capacity(plain.len());
    let mut rest = plain.as_str();
    while let Some(i) = rest.find(" at ") {
        let after = &rest[i + 4..];
        let end = after.find(char::is_whitespace).unwrap_or(after.len());
        // `FILE.rs:LINE`, then perhaps `.` and closing brackets.
        let token = after[..end].trim_end_matches(['.', ']', ')', ',', ';', ':']);
        let is_location = token.rsplit_once(':').is_some_and(|(file, line)| {
            file.ends_with(".rs") && !line.is_empty() && line.bytes().all(|b| b.is_ascii_digit())
        });
        if is_location {
            out.push_str(&rest[..i]);
            let tail = &after[token.len()..];
            rest = tail.strip_prefix('.').unwrap_or(tail);
        } else {
            out.push_str(&rest[..i + 4]);
            rest = after;
        }
    }
    out.push_str(rest);
    out.replace(" - Caused by ", ": ").trim().to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn source_locations_and_colour_codes_are_taken_out() {
        let zenoh = "Can not create a new TCP listener bound to 127.0.0.1:7447: Address already in use (os error 98) at /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-link-tcp-1.10.2/src/unicast.rs:412. - Caused by Unable to bind at /x/y.rs:3.";
        assert_eq!(
            plain_error(zenoh),
            "Can not create a new TCP listener bound to 127.0.0.1:7447: Address already in use (os error 98): Unable to bind"
        );
        assert_eq!(
            plain_error("\u{1b}[2m2026\u{1b}[0m \u{1b}[33m WARN\u{1b}[0m meet at noon"),
            "2026  WARN meet at noon"
        );
        assert_eq!(
            plain_error(
                "[127.0.0.1:5: Address already in use (os error 98) at /r/tcp.rs:61.]); go"
            ),
            "[127.0.0.1:5: Address already in use (os error 98)]); go"
        );
        // Text that only looks like it stays.
        assert_eq!(plain_error("look at x.rs: fine"), "look at x.rs: fine");
    }

    #[test]
    fn tls_paths_are_relative_to_the_configuration_and_flags_replace_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let certs = dir.path().join("copied/certs");
        std::fs::create_dir_all(&certs).unwrap();
        for f in ["ca.pem", "r.pem", "r.key"] {
            std::fs::write(certs.join(f), "x").unwrap();
        }
        let file = certs.join("r.json5");
        std::fs::write(
            &file,
            r#"{ mode: "client", connect: { endpoints: ["tls/localhost:7447"] },
                 listen: { endpoints: { router: ["tls/127.0.0.1:7447"], peer: [] } },
                 transport: { link: { tls: { root_ca_certificate: "ca.pem",
                   connect_certificate: "r.pem", connect_private_key: "r.key" } } } }"#,
        )
        .unwrap();
        let options = SessionOptions {
            config_file: Some(file.clone()),
            ..SessionOptions::default()
        };
        let config = options.config().unwrap();
        let ca: String = serde_json::from_str(
            &config
                .get_json("transport/link/tls/root_ca_certificate")
                .unwrap(),
        )
        .unwrap();
        assert_eq!(Path::new(&ca), certs.join("ca.pem"));
        assert_eq!(endpoints(&config, "connect"), ["tls/localhost:7447"]);
        // The file's endpoints stand unless a flag gives others.
        let router = SessionOptions {
            mode: Some("router".into()),
            ..options.clone()
        };
        assert_eq!(
            endpoints(&router.config().unwrap(), "listen"),
            ["tls/127.0.0.1:7447"]
        );
        let flagged = SessionOptions {
            listen: vec!["tcp/127.0.0.1:9".into()],
            ..router
        };
        assert_eq!(
            endpoints(&flagged.config().unwrap(), "listen"),
            ["tcp/127.0.0.1:9"]
        );
        // A named file that is not there: the error says which.
        std::fs::remove_file(certs.join("r.key")).unwrap();
        let e = options.config().unwrap_err().to_string();
        assert!(
            e.contains("connect_private_key") && e.contains("r.key"),
            "{e}"
        );
    }
}
