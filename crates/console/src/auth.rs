//! Who may use the console: this page signs and uploads plans, so every
//! request needs the access token (in the URL once, then a same-site
//! cookie, or an `Authorization: Bearer` header), and a WebSocket upgrade
//! must come from one of the console's own origins (a page elsewhere cannot
//! drive a robot through the operator's browser).

use std::net::SocketAddr;
use std::path::Path;

use axum::http::HeaderMap;
use axum::http::header::{AUTHORIZATION, COOKIE, ORIGIN};

pub const COOKIE_NAME: &str = "twindrive_token";

/// The token and the origins allowed to open the console's WebSocket.
#[derive(Debug, Clone)]
pub struct Access {
    token: String,
    origins: Vec<String>,
}

/// A new random token: 24 bytes from the operating system, as hex.
pub fn new_token() -> anyhow::Result<String> {
    let mut bytes = [0u8; 24];
    getrandom::fill(&mut bytes)
        .map_err(|e| anyhow::anyhow!("no random bytes for the access token: {e}"))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// The token kept in `path` (made with mode 0600 when missing), so a
/// restarted console accepts the pages that were open.
pub fn token_in(path: &Path) -> anyhow::Result<String> {
    match std::fs::read_to_string(path) {
        Ok(t) if t.trim().len() >= 32 && t.trim().bytes().all(|b| b.is_ascii_hexdigit()) => {
            Ok(t.trim().to_owned())
        }
        Ok(_) => anyhow::bail!(
            "{}: not a console token (at least 32 hex digits); delete it for a new one",
            path.display()
        ),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let token = new_token()?;
            if let Some(dir) = path.parent() {
                std::fs::create_dir_all(dir)?;
            }
            let tmp = path.with_extension("tmp");
            {
                use std::io::Write;
                let mut options = std::fs::OpenOptions::new();
                options.write(true).create(true).truncate(true);
                #[cfg(unix)]
                {
                    use std::os::unix::fs::OpenOptionsExt;
                    options.mode(0o600);
                }
                let mut f = options.open(&tmp)?;
                f.write_all(token.as_bytes())?;
                f.sync_all()?;
            }
            std::fs::rename(&tmp, path)?;
            Ok(token)
        }
        Err(e) => Err(anyhow::anyhow!("reading {}: {e}", path.display())),
    }
}

/// Equal in constant time (for equal lengths).
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

impl Access {
    /// Access with `token` for a console listening on `listen`; `extra`
    /// origins (`http://host:port`) are allowed too (a reverse proxy, say).
    pub fn new(token: String, listen: SocketAddr, extra: &[String]) -> Self {
        let port = listen.port();
        let mut origins = vec![
            format!("http://127.0.0.1:{port}"),
            format!("http://localhost:{port}"),
            format!("http://[::1]:{port}"),
        ];
        if !listen.ip().is_unspecified() {
            origins.push(format!("http://{listen}"));
        }
        origins.extend(extra.iter().map(|o| o.trim_end_matches('/').to_owned()));
        Self { token, origins }
    }

    pub fn token(&self) -> &str {
        &self.token
    }

    /// Whether the request carries the token: `?token=` in `query_token`,
    /// the cookie, or a bearer header.
    pub fn token_ok(&self, headers: &HeaderMap, query_token: Option<&str>) -> bool {
        let want = self.token.as_bytes();
        if query_token.is_some_and(|t| same(t.as_bytes(), want)) {
            return true;
        }
        let bearer = headers
            .get_all(AUTHORIZATION)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .filter_map(|v| v.strip_prefix("Bearer "))
            .any(|t| same(t.trim().as_bytes(), want));
        if bearer {
            return true;
        }
        headers
            .get_all(COOKIE)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(';'))
            .filter_map(|c| c.trim().split_once('='))
            .any(|(k, v)| k == COOKIE_NAME && same(v.as_bytes(), want))
    }

    /// Whether a WebSocket upgrade comes from one of the console's origins.
    pub fn origin_ok(&self, headers: &HeaderMap) -> bool {
        let origins: Vec<&str> = headers
            .get_all(ORIGIN)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .collect();
        // Exactly one Origin header, and it must be ours.
        origins.len() == 1 && self.origins.iter().any(|o| o == origins[0])
    }

    /// The cookie that keeps the token for later requests of this page.
    pub fn cookie(&self) -> String {
        format!(
            "{COOKIE_NAME}={}; HttpOnly; SameSite=Strict; Path=/",
            self.token
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    fn access() -> Access {
        Access::new(
            "ab".repeat(24),
            "127.0.0.1:8080".parse().unwrap(),
            &["https://ops.example:443/".into()],
        )
    }

    #[test]
    fn the_token_is_needed_in_one_of_three_places() {
        let a = access();
        let none = HeaderMap::new();
        assert!(!a.token_ok(&none, None));
        assert!(!a.token_ok(&none, Some("ab")));
        assert!(!a.token_ok(&none, Some(&"ac".repeat(24))));
        assert!(a.token_ok(&none, Some(&"ab".repeat(24))));
        let mut cookie = HeaderMap::new();
        cookie.insert(
            COOKIE,
            HeaderValue::from_str(&format!("other=1; {COOKIE_NAME}={}", "ab".repeat(24))).unwrap(),
        );
        assert!(a.token_ok(&cookie, None));
        let mut wrong = HeaderMap::new();
        wrong.insert(
            COOKIE,
            HeaderValue::from_str(&format!("{COOKIE_NAME}=x{}", "ab".repeat(24))).unwrap(),
        );
        assert!(!a.token_ok(&wrong, None));
        let mut bearer = HeaderMap::new();
        bearer.insert(
            AUTHORIZATION,
            HeaderValue::from_str(&format!("Bearer {}", "ab".repeat(24))).unwrap(),
        );
        assert!(a.token_ok(&bearer, None));
    }

    #[test]
    fn only_the_console_s_own_origins_open_a_websocket() {
        let a = access();
        let with = |o: &str| {
            let mut h = HeaderMap::new();
            h.insert(ORIGIN, HeaderValue::from_str(o).unwrap());
            h
        };
        assert!(a.origin_ok(&with("http://127.0.0.1:8080")));
        assert!(a.origin_ok(&with("http://localhost:8080")));
        assert!(a.origin_ok(&with("https://ops.example:443")));
        assert!(!a.origin_ok(&with("http://127.0.0.1:8081")));
        assert!(!a.origin_ok(&with("http://evil.example")));
        assert!(!a.origin_ok(&with("null")));
        assert!(!a.origin_ok(&HeaderMap::new()));
    }

    #[test]
    fn a_token_file_is_made_once_and_kept() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("console.token");
        let first = token_in(&path).unwrap();
        assert_eq!(first.len(), 48);
        assert_eq!(token_in(&path).unwrap(), first);
        std::fs::write(&path, "short").unwrap();
        assert!(
            token_in(&path)
                .unwrap_err()
                .to_string()
                .contains("not a console token")
        );
    }
}
