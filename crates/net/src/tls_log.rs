//! A TLS listener's refused clients in the log: said once, then counted.
//!
//! zenoh's TLS listener logs every handshake that fails as an accept error
//! with "Hint: increase the system open file limit" (its accept loop's
//! guess at the usual cause of a failed `accept`): a client the router's
//! TLS refuses (no certificate, another CA's, plain TCP on the TLS port)
//! retrying every second fills a router's log with a line that points at
//! the wrong thing. [`TlsRefusals`], a `tracing` layer, takes those lines
//! out and says instead what happened: the first refusal at once, in
//! words (`TLS refused a client: it offered no certificate`), then at most
//! one line every [`SUMMARY_PERIOD`] with how many more and why. A
//! failed accept that is the file limit (`Too many open files`) keeps
//! zenoh's words, at most one line every [`SUMMARY_PERIOD`] as well.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use tracing::field::{Field, Visit};
use tracing::{Event, Subscriber};
use tracing_subscriber::layer::{Context, Layer};

/// At most one line about refused TLS clients this often.
pub const SUMMARY_PERIOD: Duration = Duration::from_secs(10);

/// The end of zenoh's accept-error line (zenoh-link-tls's accept loop).
const ZENOH_HINT: &str = ". Hint: increase the system open file limit.";

/// Whether `target` is zenoh's TLS link (its accept loop logs there).
fn is_tls_link(target: &str) -> bool {
    target.starts_with("zenoh_link_tls")
}

/// What a failed TLS accept (zenoh's error text) says about the client,
/// for people; `None` when it is not a handshake's failure but the
/// process's (the file limit, say), which zenoh's hint is right about.
pub fn explain(error: &str) -> Option<&'static str> {
    let e = error.to_ascii_lowercase();
    let known: [(&[&str], &str); 8] = [
        (&["too many open files", "os error 24", "os error 23"], ""),
        (
            &[
                "invalidcontenttype",
                "corrupt message",
                "unknownprotocolversion",
            ],
            "it spoke plain TCP (or something else that is not TLS) to this TLS endpoint",
        ),
        (
            &["peer sent no certificates", "certificaterequired"],
            "it offered no client certificate",
        ),
        (
            &["unknownissuer", "badsignature"],
            "its certificate is not signed by the CA this endpoint trusts (another fleet's?)",
        ),
        (
            &[
                "alert: unknownca",
                "alert: badcertificate",
                "alert: certificateunknown",
                "alert: certificateexpired",
                "alert: decrypterror",
            ],
            "it does not accept this endpoint's certificate (it trusts another CA, or connected by a name the certificate lacks)",
        ),
        (
            &["expired", "notvalidyet"],
            "its certificate is out of its validity period",
        ),
        (
            &["timeout during tls handshake"],
            "it did not finish the TLS handshake in time (it connected and said nothing TLS understands)",
        ),
        (
            &["eof", "end of file", "connection reset"],
            "it closed the connection during the TLS handshake (a port check?)",
        ),
    ];
    for (needles, why) in known {
        if needles.iter().any(|n| e.contains(n)) {
            return (!why.is_empty()).then_some(why);
        }
    }
    Some("its TLS handshake failed")
}

/// The layer: add it to the subscriber (`.with(TlsRefusals::new())`).
#[derive(Clone)]
pub struct TlsRefusals {
    shared: Arc<Shared>,
}

struct Shared {
    state: Mutex<State>,
    wake: Condvar,
}

#[derive(Default)]
struct State {
    /// Refusals not yet said: by explanation, how many and the latest
    /// error text.
    pending: BTreeMap<&'static str, (u64, String)>,
    /// The reporter thread runs.
    started: bool,
    /// When a file-limit line was last let through.
    file_limit_said: Option<Instant>,
}

impl Default for TlsRefusals {
    fn default() -> Self {
        Self::new()
    }
}

impl TlsRefusals {
    pub fn new() -> Self {
        Self {
            shared: Arc::new(Shared {
                state: Mutex::new(State::default()),
                wake: Condvar::new(),
            }),
        }
    }

    /// Notes a refusal; the reporter says it.
    fn refused(&self, why: &'static str, error: String) {
        let mut state = self.shared.state.lock().unwrap_or_else(|p| p.into_inner());
        let entry = state.pending.entry(why).or_insert((0, String::new()));
        entry.0 += 1;
        entry.1 = error;
        if !state.started {
            state.started = true;
            let shared = self.shared.clone();
            // The lines are said from a thread of their own: an event
            // emitted while the subscriber decides on another would be
            // lost (tracing does not dispatch inside a dispatch).
            let spawned = std::thread::Builder::new()
                .name("tls-refusals".into())
                .spawn(move || report(&shared));
            if spawned.is_err() {
                state.started = false;
            }
        }
        drop(state);
        self.shared.wake.notify_one();
    }
}

/// The reporter: says a refusal as soon as it comes after a quiet while,
/// then what came during each [`SUMMARY_PERIOD`] after a line.
fn report(shared: &Shared) {
    // The first refusal started this thread: it came after a quiet while.
    let mut first = true;
    loop {
        let (pending, after_quiet) = {
            let mut state = shared.state.lock().unwrap_or_else(|p| p.into_inner());
            let mut waited = std::mem::take(&mut first);
            while state.pending.is_empty() {
                waited = true;
                state = shared.wake.wait(state).unwrap_or_else(|p| p.into_inner());
            }
            (std::mem::take(&mut state.pending), waited)
        };
        for line in lines(&pending, !after_quiet) {
            tracing::warn!(target: "twindrive_net::tls", "{line}");
        }
        std::thread::sleep(SUMMARY_PERIOD);
    }
}

/// What to say of `pending` refusals: one after a quiet while in full
/// (`TLS refused a client: WHY (zenoh: ERROR)`), those of a period since
/// the last line (`again`) counted.
fn lines(pending: &BTreeMap<&'static str, (u64, String)>, again: bool) -> Vec<String> {
    let total: u64 = pending.values().map(|(n, _)| n).sum();
    if !again && total == 1 {
        let (why, (_, error)) = pending.iter().next().expect("one refusal");
        return vec![format!(
            "TLS refused a client: {why} (zenoh: {error}); said again at most every {} s",
            SUMMARY_PERIOD.as_secs()
        )];
    }
    let mut line = format!(
        "TLS refused {total} client connection(s) in the last {} s:",
        SUMMARY_PERIOD.as_secs()
    );
    for (k, (why, (n, error))) in pending.iter().enumerate() {
        let sep = if k == 0 { " " } else { "; " };
        let _ = write!(line, "{sep}{n} because {why} (zenoh: {error})");
    }
    vec![line]
}

/// The text of an event's `message` field.
#[derive(Default)]
struct Message(String);

impl Visit for Message {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.0 = value.to_string();
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}");
        }
    }
}

impl<S: Subscriber> Layer<S> for TlsRefusals {
    fn event_enabled(&self, event: &Event<'_>, _ctx: Context<'_, S>) -> bool {
        let meta = event.metadata();
        if *meta.level() != tracing::Level::WARN || !is_tls_link(meta.target()) {
            return true;
        }
        let mut message = Message::default();
        event.record(&mut message);
        let Some(error) = message.0.strip_suffix(ZENOH_HINT) else {
            return true;
        };
        match explain(error) {
            Some(why) => {
                self.refused(why, crate::plain_error(error));
                false
            }
            None => {
                // The file limit indeed: zenoh's line, once a period.
                let mut state = self.shared.state.lock().unwrap_or_else(|p| p.into_inner());
                let due = state
                    .file_limit_said
                    .is_none_or(|t| t.elapsed() >= SUMMARY_PERIOD);
                if due {
                    state.file_limit_said = Some(Instant::now());
                }
                due
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_refusal_is_explained_and_the_file_limit_is_not_one() {
        for (error, has) in [
            (
                "received corrupt message of type InvalidContentType",
                "plain TCP",
            ),
            ("peer sent no certificates", "no client certificate"),
            (
                "invalid peer certificate: UnknownIssuer",
                "not signed by the CA",
            ),
            ("received fatal alert: UnknownCA", "trusts another CA"),
            ("Timeout during TLS handshake", "in time"),
            ("tls handshake eof", "closed the connection"),
            ("something new", "handshake failed"),
        ] {
            let why = explain(error).unwrap();
            assert!(why.contains(has), "{error}: {why}");
        }
        assert_eq!(explain("Too many open files (os error 24)"), None);
    }

    #[test]
    fn the_first_refusal_is_said_in_full_and_later_ones_counted() {
        let mut pending = BTreeMap::new();
        pending.insert(
            explain("peer sent no certificates").unwrap(),
            (1, "peer sent no certificates".to_string()),
        );
        let first = lines(&pending, false);
        assert_eq!(first.len(), 1);
        assert!(
            first[0].starts_with("TLS refused a client: it offered no client certificate"),
            "{first:?}"
        );
        pending.insert(
            explain("received corrupt message of type InvalidContentType").unwrap(),
            (
                9,
                "received corrupt message of type InvalidContentType".to_string(),
            ),
        );
        let later = lines(&pending, true);
        assert!(
            later[0].starts_with("TLS refused 10 client connection(s) in the last 10 s: ")
                && later[0].contains("9 because it spoke plain TCP")
                && later[0].contains("1 because it offered no client certificate"),
            "{later:?}"
        );
        assert!(!later[0].contains("open file limit"), "{later:?}");
    }
}
