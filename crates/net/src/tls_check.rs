//! Why an endpoint's TLS will not take this process, found out by asking
//! it.
//!
//! zenoh says only that it was "unable to connect" when a router's TLS
//! refuses a client (no certificate offered, a certificate of another CA,
//! plain TCP on the TLS port); the reason stays in its link layer. When a
//! session does not connect, [`probe`] goes through the handshake itself
//! with rustls, with the very files the zenoh configuration names
//! ([`TlsIdentity`]), and tells what stopped it: the alert the router
//! sent, the check of the router's certificate that failed, or a peer that
//! answers a TLS greeting on a `tcp/` endpoint. A probe takes one TCP
//! connection and at most its time limit; it sends no zenoh message.

use std::io::ErrorKind;
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::client::{ClientSessionStore, Resumption, WebPkiServerVerifier};
use rustls::crypto::CryptoProvider;
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName, UnixTime};
use rustls::{AlertDescription, CertificateError, ClientConfig, ClientConnection};

/// What this process trusts and shows on a TLS link: the files of a zenoh
/// configuration's `transport/link/tls` section.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsIdentity {
    /// The CA whose certificates this process trusts (`root_ca_certificate`;
    /// without one, only the public web's CAs, as zenoh).
    pub root_ca: Option<PathBuf>,
    /// The certificate and key this process shows (`connect_certificate`,
    /// `connect_private_key`): only with `enable_mtls`, as zenoh.
    pub certificate: Option<(PathBuf, PathBuf)>,
    /// Whether the router's certificate must name the endpoint's host
    /// (`verify_name_on_connect`, on unless the configuration turns it off).
    pub verify_name: bool,
}

impl Default for TlsIdentity {
    fn default() -> Self {
        Self {
            root_ca: None,
            certificate: None,
            verify_name: true,
        }
    }
}

/// What a probe of an endpoint found.
#[derive(Debug, Clone, PartialEq)]
pub enum Finding {
    /// No TCP connection there (nothing listens, or the network does not
    /// reach it): the error.
    NotListening(String),
    /// The endpoint's TLS will not take this process, and why.
    Refused(Refusal),
    /// Nothing against this process: the TLS handshake completed and the
    /// router kept the connection, or a `tcp/` endpoint that does not speak
    /// TLS, or an endpoint the probe does not look into (UDP, QUIC, one
    /// with its own TLS settings after `#`).
    NothingFound,
}

/// Why an endpoint's TLS refused this process.
#[derive(Debug, Clone, PartialEq)]
pub enum Refusal {
    /// The router asks for a client certificate and this process showed
    /// none.
    NoClientCertificate,
    /// The router rejected the certificate this process showed (the
    /// router's alert: `unknown_ca`, `bad_certificate`, ...).
    ClientCertificateRejected {
        certificate: PathBuf,
        alert: String,
    },
    /// The router's certificate does not chain to a CA this process trusts.
    RouterNotTrusted {
        root_ca: Option<PathBuf>,
    },
    /// The router's certificate is not for the endpoint's host name.
    RouterWrongName {
        host: String,
    },
    /// The router's certificate is out of its validity period.
    RouterCertificateExpired,
    RouterCertificateNotYetValid,
    /// A `tcp/` endpoint whose peer answered a TLS greeting: it is a TLS
    /// listener, and this process spoke plain TCP to it.
    PlainTcpToTls {
        tls_endpoint: String,
    },
    /// A `tls/` endpoint whose peer does not speak TLS.
    NotTls {
        tcp_endpoint: String,
        what: String,
    },
    /// The peer took the connection and said nothing to the TLS greeting
    /// within the probe's time.
    NoAnswer {
        within_s: f64,
        tcp_endpoint: String,
    },
    /// Anything else the handshake ended with.
    Other(String),
}

/// What to do, said once for the refusals a fleet's files fix.
const USE_FLEET_FILES: &str = "use the zenoh configuration `twindrive certs` wrote for this process (--zenoh-config master.json5, or ID.json5 for robot ID), from the same `certs` run as the router's";

impl Refusal {
    /// Why, in words.
    pub fn reason(&self) -> String {
        match self {
            Self::NoClientCertificate => {
                "the router requires a client certificate and this process offered none (its configuration has no connect_certificate, or enable_mtls is off)".into()
            }
            Self::ClientCertificateRejected { certificate, alert } => format!(
                "the router rejected this process's certificate {} (its alert: {alert}): it is not signed by the CA the router trusts",
                certificate.display()
            ),
            Self::RouterNotTrusted { root_ca: Some(ca) } => format!(
                "the router's certificate is not signed by the CA this process trusts ({})",
                ca.display()
            ),
            Self::RouterNotTrusted { root_ca: None } => {
                "the router's certificate is not signed by a CA this process trusts (its configuration names no root_ca_certificate: only the public web's CAs)".into()
            }
            Self::RouterWrongName { host } => {
                format!("the router's certificate is not made out to {host}")
            }
            Self::RouterCertificateExpired => "the router's certificate has expired".into(),
            Self::RouterCertificateNotYetValid => {
                "the router's certificate is not valid yet (is this machine's clock right?)".into()
            }
            Self::PlainTcpToTls { .. } => {
                "the peer speaks TLS and this process spoke plain TCP".into()
            }
            Self::NotTls { what, .. } => {
                format!("the peer does not speak TLS ({what})")
            }
            Self::NoAnswer { within_s, .. } => format!(
                "the peer took the connection but did not answer the TLS handshake in {within_s:.0} s"
            ),
            Self::Other(what) => what.clone(),
        }
    }

    /// What to do about it.
    pub fn fix(&self) -> String {
        match self {
            Self::NoClientCertificate
            | Self::ClientCertificateRejected { .. }
            | Self::RouterNotTrusted { .. } => USE_FLEET_FILES.into(),
            Self::RouterWrongName { .. } => "connect by a name the router's certificate holds (`twindrive certs --router-host NAME` makes it out to NAME)".into(),
            Self::RouterCertificateExpired | Self::RouterCertificateNotYetValid => {
                "make the fleet's certificates again with `twindrive certs`".into()
            }
            Self::PlainTcpToTls { tls_endpoint } => format!(
                "connect over TLS ({tls_endpoint}, by a name the router's certificate holds) and {USE_FLEET_FILES}"
            ),
            Self::NotTls { tcp_endpoint, .. } | Self::NoAnswer { tcp_endpoint, .. } => format!(
                "if it is a plain TCP listener, connect to {tcp_endpoint}; if it should be the fleet's TLS router, start it with its router.json5"
            ),
            Self::Other(_) => USE_FLEET_FILES.into(),
        }
    }

    /// The whole message: the endpoint, that TLS refused this process,
    /// why, and what to do.
    pub fn message(&self, endpoint: &str) -> String {
        format!(
            "connecting to {endpoint}: TLS refused this process: {}; {}",
            self.reason(),
            self.fix()
        )
    }
}

/// An endpoint (`tcp/HOST:PORT`, `tls/HOST:PORT`) in parts: its protocol,
/// host and port; `None` for what a probe does not look into.
fn parse_endpoint(endpoint: &str) -> Option<(&str, &str, u16)> {
    let (protocol, rest) = endpoint.split_once('/')?;
    // Metadata (`?`) says nothing to the link; a configuration of its own
    // (`#`) the probe would not see.
    if rest.contains('#') {
        return None;
    }
    let address = rest.split('?').next()?;
    let (host, port) = address.rsplit_once(':')?;
    let host = host.trim_start_matches('[').trim_end_matches(']');
    Some((protocol, host, port.parse().ok()?))
}

/// Probes `endpoint` as this process would connect to it, within `limit`.
pub fn probe(endpoint: &str, identity: &TlsIdentity, limit: Duration) -> Finding {
    let deadline = Instant::now() + limit;
    let Some((protocol, host, port)) = parse_endpoint(endpoint) else {
        return Finding::NothingFound;
    };
    let swap = |to: &str| format!("{to}/{}", &endpoint[protocol.len() + 1..]);
    let (config, tls_endpoint) = match protocol {
        "tls" => match client_config(identity) {
            Ok(c) => (c, None),
            // A file zenoh could not read either: zenoh says so itself.
            Err(_) => return Finding::NothingFound,
        },
        "tcp" => (greeting_config(), Some(swap("tls"))),
        _ => return Finding::NothingFound,
    };
    let Ok(server_name) = ServerName::try_from(host.to_string()) else {
        return Finding::NothingFound;
    };
    let mut socket = match connect(host, port, deadline) {
        Ok(s) => s,
        Err(e) => return Finding::NotListening(e),
    };
    let ticket = config.ticket.clone();
    let verified = config.verifier.clone();
    let Ok(mut tls) = ClientConnection::new(Arc::new(config.rustls), server_name) else {
        return Finding::NothingFound;
    };
    let offered = identity.certificate.is_some() && tls_endpoint.is_none();
    let ended = exchange(&mut tls, &mut socket, deadline, &ticket);
    if let Some(tls_endpoint) = tls_endpoint {
        // A plain TCP endpoint: whatever answered the greeting as TLS
        // does (a certificate, or an alert) is a TLS listener.
        let answered_as_tls = verified.saw_certificate.load(Ordering::SeqCst)
            || matches!(ended, Ended::Failed(rustls::Error::AlertReceived(_)));
        return if answered_as_tls {
            Finding::Refused(Refusal::PlainTcpToTls { tls_endpoint })
        } else {
            Finding::NothingFound
        };
    }
    match ended {
        Ended::Accepted => Finding::NothingFound,
        Ended::Failed(e) => Finding::Refused(refusal(&e, identity, host, offered, &swap("tcp"))),
        Ended::Closed { handshaking: true } => Finding::Refused(Refusal::Other(
            "the peer closed the connection during the TLS handshake".into(),
        )),
        Ended::Closed { handshaking: false } => Finding::Refused(Refusal::Other(format!(
            "the router closed the connection right after the TLS handshake{}",
            if offered {
                ""
            } else {
                " (this process offered no client certificate)"
            }
        ))),
        Ended::Silent { handshaking: true } => Finding::Refused(Refusal::NoAnswer {
            within_s: limit.as_secs_f64(),
            tcp_endpoint: swap("tcp"),
        }),
        // The handshake completed and nothing came against it.
        Ended::Silent { handshaking: false } => Finding::NothingFound,
    }
}

/// The first of `host:port`'s addresses that takes a TCP connection.
fn connect(host: &str, port: u16, deadline: Instant) -> Result<TcpStream, String> {
    let addresses: Vec<SocketAddr> = (host, port)
        .to_socket_addrs()
        .map_err(|e| format!("{host}: {e}"))?
        .collect();
    let mut last = format!("{host}: no address");
    for address in addresses {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        match TcpStream::connect_timeout(&address, left) {
            Ok(s) => return Ok(s),
            Err(e) => last = format!("{address}: {e}"),
        }
    }
    Err(last)
}

/// How an exchange ended.
enum Ended {
    /// Handshake done and the router sent its session tickets: it took
    /// this process's certificate (if it asked for one).
    Accepted,
    /// rustls stopped it: an alert from the peer, or a check of ours.
    Failed(rustls::Error),
    /// The peer closed the connection (no alert).
    Closed { handshaking: bool },
    /// The time ran out.
    Silent { handshaking: bool },
}

/// Drives the handshake until the router accepts (its tickets come once
/// it has checked this process's certificate), refuses, closes, or the
/// deadline.
fn exchange(
    tls: &mut ClientConnection,
    socket: &mut TcpStream,
    deadline: Instant,
    ticket: &TicketSeen,
) -> Ended {
    loop {
        while tls.wants_write() {
            if tls.write_tls(socket).is_err() {
                return Ended::Closed {
                    handshaking: tls.is_handshaking(),
                };
            }
        }
        // TLS 1.3 checks the client's certificate after the client is done
        // (the tickets say the router took it); TLS 1.2 before.
        let tls12 = tls.protocol_version() == Some(rustls::ProtocolVersion::TLSv1_2);
        if !tls.is_handshaking() && (tls12 || ticket.0.load(Ordering::SeqCst)) {
            return Ended::Accepted;
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Ended::Silent {
                handshaking: tls.is_handshaking(),
            };
        }
        let _ = socket.set_read_timeout(Some(left));
        match tls.read_tls(socket) {
            Ok(0) => {
                return Ended::Closed {
                    handshaking: tls.is_handshaking(),
                };
            }
            Ok(_) => {
                if let Err(e) = tls.process_new_packets() {
                    // Our alert, if any, on its way out.
                    let _ = tls.write_tls(socket);
                    return Ended::Failed(e);
                }
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(_) => {
                return Ended::Closed {
                    handshaking: tls.is_handshaking(),
                };
            }
        }
    }
}

/// What a handshake's error says about this process and the router.
fn refusal(
    e: &rustls::Error,
    identity: &TlsIdentity,
    host: &str,
    offered: bool,
    tcp_endpoint: &str,
) -> Refusal {
    use rustls::Error as E;
    match e {
        E::InvalidCertificate(c) => match c {
            CertificateError::UnknownIssuer | CertificateError::BadSignature => {
                Refusal::RouterNotTrusted {
                    root_ca: identity.root_ca.clone(),
                }
            }
            CertificateError::NotValidForName | CertificateError::NotValidForNameContext { .. } => {
                Refusal::RouterWrongName { host: host.into() }
            }
            CertificateError::Expired | CertificateError::ExpiredContext { .. } => {
                Refusal::RouterCertificateExpired
            }
            CertificateError::NotValidYet | CertificateError::NotValidYetContext { .. } => {
                Refusal::RouterCertificateNotYetValid
            }
            other => Refusal::Other(format!("the router's certificate: {other:?}")),
        },
        E::AlertReceived(alert) => {
            use AlertDescription as A;
            let about_certificate = matches!(
                alert,
                A::CertificateRequired
                    | A::UnknownCA
                    | A::BadCertificate
                    | A::CertificateUnknown
                    | A::UnsupportedCertificate
                    | A::CertificateExpired
                    | A::CertificateRevoked
                    | A::AccessDenied
                    | A::DecryptError
            );
            match &identity.certificate {
                None if *alert == A::CertificateRequired => Refusal::NoClientCertificate,
                Some((certificate, _)) if offered && about_certificate => {
                    Refusal::ClientCertificateRejected {
                        certificate: certificate.clone(),
                        alert: alert_name(*alert),
                    }
                }
                _ => Refusal::Other(format!(
                    "the router ended the TLS handshake with the alert {}",
                    alert_name(*alert)
                )),
            }
        }
        E::InvalidMessage(m) => Refusal::NotTls {
            tcp_endpoint: tcp_endpoint.into(),
            what: format!("it answered with something that is not a TLS record: {m:?}"),
        },
        other => Refusal::Other(format!("the TLS handshake failed: {other}")),
    }
}

/// A TLS alert's name as the standard writes it (`unknown_ca`).
fn alert_name(alert: AlertDescription) -> String {
    let mut out = String::new();
    let mut prev_lower = false;
    for c in format!("{alert:?}").chars() {
        // `UnknownCA` → `unknown_ca`: a run of capitals is one word.
        if c.is_ascii_uppercase() && prev_lower {
            out.push('_');
        }
        prev_lower = c.is_ascii_lowercase();
        out.push(c.to_ascii_lowercase());
    }
    out
}

/// A rustls client configuration, with what the probe watches.
struct ProbeConfig {
    rustls: ClientConfig,
    verifier: Arc<Watching>,
    ticket: Arc<TicketSeen>,
}

fn provider() -> Arc<CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// The client zenoh would be, with `identity`'s files.
fn client_config(identity: &TlsIdentity) -> Result<ProbeConfig, String> {
    let provider = provider();
    let mut roots = rustls::RootCertStore::empty();
    if let Some(ca) = &identity.root_ca {
        for cert in certificates(ca)? {
            roots
                .add(cert)
                .map_err(|e| format!("{}: {e}", ca.display()))?;
        }
    }
    let webpki = if roots.is_empty() {
        None
    } else {
        Some(
            WebPkiServerVerifier::builder_with_provider(Arc::new(roots), provider.clone())
                .build()
                .map_err(|e| e.to_string())?,
        )
    };
    let verifier = Arc::new(Watching {
        webpki,
        verify_name: identity.verify_name,
        provider: provider.clone(),
        saw_certificate: AtomicBool::new(false),
    });
    let builder = ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| e.to_string())?
        .dangerous()
        .with_custom_certificate_verifier(verifier.clone());
    let mut rustls = match &identity.certificate {
        Some((cert, key)) => {
            let key =
                PrivateKeyDer::from_pem_file(key).map_err(|e| format!("{}: {e}", key.display()))?;
            builder
                .with_client_auth_cert(certificates(cert)?, key)
                .map_err(|e| e.to_string())?
        }
        None => builder.with_no_client_auth(),
    };
    let ticket = Arc::new(TicketSeen::default());
    rustls.resumption = Resumption::store(ticket.clone());
    Ok(ProbeConfig {
        rustls,
        verifier,
        ticket,
    })
}

/// A greeting that only asks whether the peer speaks TLS: it takes any
/// certificate (and ends the exchange there).
fn greeting_config() -> ProbeConfig {
    let provider = provider();
    let verifier = Arc::new(Watching {
        webpki: None,
        verify_name: false,
        provider: provider.clone(),
        saw_certificate: AtomicBool::new(false),
    });
    let mut rustls = ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .expect("ring supports the default versions")
        .dangerous()
        .with_custom_certificate_verifier(verifier.clone())
        .with_no_client_auth();
    let ticket = Arc::new(TicketSeen::default());
    rustls.resumption = Resumption::store(ticket.clone());
    ProbeConfig {
        rustls,
        verifier,
        ticket,
    }
}

fn certificates(path: &Path) -> Result<Vec<CertificateDer<'static>>, String> {
    CertificateDer::pem_file_iter(path)
        .and_then(|certs| certs.collect::<Result<Vec<_>, _>>())
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// The router's certificate checked as zenoh checks it (webpki against the
/// trusted CA, the name unless told not to); notes that the peer showed
/// one. Without a CA (the greeting), it refuses every certificate as from
/// an unknown issuer once it has seen it.
#[derive(Debug)]
struct Watching {
    webpki: Option<Arc<WebPkiServerVerifier>>,
    verify_name: bool,
    provider: Arc<CryptoProvider>,
    saw_certificate: AtomicBool,
}

impl ServerCertVerifier for Watching {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        server_name: &ServerName<'_>,
        ocsp_response: &[u8],
        now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        self.saw_certificate.store(true, Ordering::SeqCst);
        let Some(webpki) = &self.webpki else {
            return Err(rustls::Error::InvalidCertificate(
                CertificateError::UnknownIssuer,
            ));
        };
        match webpki.verify_server_cert(end_entity, intermediates, server_name, ocsp_response, now)
        {
            Err(rustls::Error::InvalidCertificate(
                CertificateError::NotValidForName | CertificateError::NotValidForNameContext { .. },
            )) if !self.verify_name => Ok(ServerCertVerified::assertion()),
            other => other,
        }
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &rustls::DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls12_signature(
            message,
            cert,
            dss,
            &self.provider.signature_verification_algorithms,
        )
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &rustls::DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls13_signature(
            message,
            cert,
            dss,
            &self.provider.signature_verification_algorithms,
        )
    }

    fn supported_verify_schemes(&self) -> Vec<rustls::SignatureScheme> {
        self.provider
            .signature_verification_algorithms
            .supported_schemes()
    }
}

/// A session store that keeps nothing and notes that the server sent a
/// TLS 1.3 ticket: a server sends them once it has taken the client's
/// Finished (and its certificate).
#[derive(Debug, Default)]
struct TicketSeen(AtomicBool);

impl ClientSessionStore for TicketSeen {
    fn set_kx_hint(&self, _: ServerName<'static>, _: rustls::NamedGroup) {}

    fn kx_hint(&self, _: &ServerName<'_>) -> Option<rustls::NamedGroup> {
        None
    }

    fn set_tls12_session(
        &self,
        _: ServerName<'static>,
        _: rustls::client::Tls12ClientSessionValue,
    ) {
    }

    fn tls12_session(&self, _: &ServerName<'_>) -> Option<rustls::client::Tls12ClientSessionValue> {
        None
    }

    fn remove_tls12_session(&self, _: &ServerName<'static>) {}

    fn insert_tls13_ticket(
        &self,
        _: ServerName<'static>,
        _: rustls::client::Tls13ClientSessionValue,
    ) {
        self.0.store(true, Ordering::SeqCst);
    }

    fn take_tls13_ticket(
        &self,
        _: &ServerName<'static>,
    ) -> Option<rustls::client::Tls13ClientSessionValue> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Read, Write};
    use std::net::TcpListener;

    #[test]
    fn endpoints_and_alerts_in_parts_and_words() {
        assert_eq!(
            parse_endpoint("tls/localhost:7447"),
            Some(("tls", "localhost", 7447))
        );
        assert_eq!(
            parse_endpoint("tcp/[::1]:9?prio=1"),
            Some(("tcp", "::1", 9))
        );
        assert_eq!(
            parse_endpoint("tls/localhost:7447#root_ca_certificate=x"),
            None
        );
        assert_eq!(parse_endpoint("localhost:7447"), None);
        assert_eq!(alert_name(AlertDescription::UnknownCA), "unknown_ca");
        assert_eq!(
            alert_name(AlertDescription::CertificateRequired),
            "certificate_required"
        );
        assert_eq!(alert_name(AlertDescription::DecryptError), "decrypt_error");
    }

    /// A listener on loopback that answers every connection with `reply`
    /// (after reading what comes), for `n` connections.
    fn answering(reply: &'static [u8], n: usize) -> u16 {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        std::thread::spawn(move || {
            for stream in listener.incoming().take(n) {
                let Ok(mut s) = stream else { continue };
                let _ = s.set_read_timeout(Some(Duration::from_secs(2)));
                let mut buf = [0u8; 512];
                let _ = s.read(&mut buf);
                let _ = s.write_all(reply);
            }
        });
        port
    }

    #[test]
    fn a_peer_that_is_not_tls_is_told_apart_from_nothing_listening() {
        let identity = TlsIdentity::default();
        let limit = Duration::from_secs(5);
        // Nothing there.
        let closed = TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        assert!(matches!(
            probe(&format!("tls/127.0.0.1:{closed}"), &identity, limit),
            Finding::NotListening(_)
        ));
        // A tls/ endpoint whose peer answers in plain text.
        let port = answering(b"HTTP/1.1 400 Bad Request\r\n\r\n", 1);
        let endpoint = format!("tls/127.0.0.1:{port}");
        match probe(&endpoint, &identity, limit) {
            Finding::Refused(r @ Refusal::NotTls { .. }) => {
                let m = r.message(&endpoint);
                assert!(
                    m.starts_with(&format!("connecting to {endpoint}: TLS refused"))
                        && m.contains("does not speak TLS")
                        && m.contains(&format!("tcp/127.0.0.1:{port}")),
                    "{m}"
                );
            }
            other => panic!("{other:?}"),
        }
        // A tcp/ endpoint whose peer is not TLS: nothing against it.
        let port = answering(b"hello\r\n", 1);
        assert_eq!(
            probe(&format!("tcp/127.0.0.1:{port}"), &identity, limit),
            Finding::NothingFound
        );
        // What a probe does not look into.
        assert_eq!(
            probe("udp/127.0.0.1:9", &identity, limit),
            Finding::NothingFound
        );
    }
}
