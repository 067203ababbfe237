//! `twindrive certs`: a small certificate authority and certificates for a
//! fleet's zenoh over TLS with mutual authentication (`rcgen`, ECDSA P-256),
//! and the zenoh configurations that use them: the router's, with access
//! control (a robot may publish only on `twindrive/ID/down` and read only
//! `twindrive/ID/up`; the master reads and writes every robot's), the
//! master's and each robot's. Written whole or not at all; never over keys
//! that exist.

use std::path::PathBuf;

use anyhow::{Context, bail};
use rcgen::{
    BasicConstraints, CertificateParams, CertifiedIssuer, DnType, ExtendedKeyUsagePurpose, IsCa,
    KeyPair, KeyUsagePurpose,
};

/// The master's certificate's common name (the router's access control
/// knows it by it).
pub const MASTER_CN: &str = "twindrive-master";

/// What to make.
#[derive(Debug, Clone)]
pub struct CertsRequest {
    pub out: PathBuf,
    /// The robots: each gets `ID.pem`, `ID.key` and `ID.json5`, its
    /// certificate's common name its id.
    pub robots: Vec<String>,
    /// Names and addresses the router's certificate is valid for (clients
    /// check the one they connect to).
    pub router_hosts: Vec<String>,
    /// The router's port.
    pub port: u16,
    /// Certificates are valid for this many days from now.
    pub days: u32,
}

/// Writes the CA, the certificates and the configurations into
/// `request.out` (which must not exist or be empty); returns what it wrote.
pub fn write(request: &CertsRequest) -> anyhow::Result<Vec<String>> {
    let out = &request.out;
    if out.exists()
        && std::fs::read_dir(out)
            .with_context(|| format!("reading {}", out.display()))?
            .next()
            .is_some()
    {
        bail!(
            "{} is not empty: twindrive never replaces keys or certificates (choose a new directory)",
            out.display()
        );
    }
    if request.router_hosts.is_empty() {
        bail!("the router's certificate needs a host name or address");
    }
    if let Some(id) = request
        .robots
        .iter()
        .find(|id| ["router", "master", "ca"].contains(&id.as_str()))
    {
        bail!("a robot cannot be called `{id}`: its files would clash with the {id}'s");
    }
    let staging = twindrive_files::Staging::new(out, "certs")?;
    let (not_before, not_after) = validity(request.days);

    let ca_key = KeyPair::generate().context("a key for the CA")?;
    let mut ca = CertificateParams::new(Vec::<String>::new())?;
    ca.distinguished_name
        .push(DnType::CommonName, "twindrive fleet CA");
    ca.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    ca.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    (ca.not_before, ca.not_after) = (not_before, not_after);
    let ca = CertifiedIssuer::self_signed(ca, ca_key).context("the CA's certificate")?;
    write_file(&staging, "ca.pem", ca.pem().as_bytes(), 0o644)?;
    write_file(
        &staging,
        "ca.key",
        ca.key().serialize_pem().as_bytes(),
        0o600,
    )?;

    let leaf = |name: &str, cn: &str, sans: Vec<String>, server: bool| -> anyhow::Result<()> {
        let key = KeyPair::generate().with_context(|| format!("a key for {cn}"))?;
        let mut p = CertificateParams::new(sans).with_context(|| format!("{cn}'s names"))?;
        p.distinguished_name.push(DnType::CommonName, cn);
        p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        p.extended_key_usages = if server {
            vec![ExtendedKeyUsagePurpose::ServerAuth]
        } else {
            vec![ExtendedKeyUsagePurpose::ClientAuth]
        };
        (p.not_before, p.not_after) = (not_before, not_after);
        let cert = p
            .signed_by(&key, &ca)
            .with_context(|| format!("{cn}'s certificate"))?;
        write_file(
            &staging,
            &format!("{name}.pem"),
            cert.pem().as_bytes(),
            0o644,
        )?;
        write_file(
            &staging,
            &format!("{name}.key"),
            key.serialize_pem().as_bytes(),
            0o600,
        )
    };
    leaf(
        "router",
        "twindrive-router",
        request.router_hosts.clone(),
        true,
    )?;
    leaf("master", MASTER_CN, Vec::new(), false)?;
    for id in &request.robots {
        leaf(id, id, Vec::new(), false)?;
    }

    let connect = format!("tls/{}:{}", request.router_hosts[0], request.port);
    write_file(
        &staging,
        "router.json5",
        router_config(
            &listen_address(&request.router_hosts),
            request.port,
            &request.robots,
        )
        .as_bytes(),
        0o644,
    )?;
    write_file(
        &staging,
        "master.json5",
        client_config("master", &connect).as_bytes(),
        0o644,
    )?;
    for id in &request.robots {
        write_file(
            &staging,
            &format!("{id}.json5"),
            client_config(id, &connect).as_bytes(),
            0o644,
        )?;
    }
    let mut written: Vec<String> = std::fs::read_dir(staging.dir())?
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect();
    written.sort();
    staging.commit()?;
    Ok(written)
}

fn write_file(
    staging: &twindrive_files::Staging,
    name: &str,
    bytes: &[u8],
    mode: u32,
) -> anyhow::Result<()> {
    staging.write_with(name, |w| {
        use std::io::Write;
        w.write_all(bytes)?;
        Ok(())
    })?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(staging.path(name), std::fs::Permissions::from_mode(mode))
            .with_context(|| format!("setting the mode of {name}"))?;
    }
    #[cfg(not(unix))]
    let _ = mode;
    Ok(())
}

/// From an hour ago (clocks differ) to `days` from now.
fn validity(days: u32) -> (time::OffsetDateTime, time::OffsetDateTime) {
    let now = time::OffsetDateTime::now_utc();
    (
        now - time::Duration::hours(1),
        now + time::Duration::days(i64::from(days)),
    )
}

/// A file of the fleet's directory as a configuration names it: by its
/// name alone, relative to the configuration (twindrive reads it so), so
/// the directory works wherever it is copied.
fn path(name: &str) -> String {
    format!("{name:?}")
}

/// Where the router listens: on loopback only when every name it is
/// reached at is a loopback one (a fleet tried on one machine), else on
/// every interface.
fn listen_address(router_hosts: &[String]) -> String {
    let loopback = |h: &String| {
        h == "localhost"
            || h.parse::<std::net::IpAddr>()
                .is_ok_and(|ip| ip.is_loopback())
    };
    if router_hosts.iter().all(loopback) {
        "127.0.0.1".into()
    } else {
        "0.0.0.0".into()
    }
}

/// A client's configuration: through the router, over TLS, with its own
/// certificate.
fn client_config(name: &str, connect: &str) -> String {
    format!(
        r#"// `{name}`'s zenoh configuration: a client of the fleet's router over
// TLS with mutual authentication (written by `twindrive certs`). File
// names are relative to this file's directory: keep them together.
{{
  mode: "client",
  connect: {{ endpoints: ["{connect}"] }},
  scouting: {{ multicast: {{ enabled: false }} }},
  transport: {{
    link: {{
      tls: {{
        root_ca_certificate: {ca},
        connect_certificate: {cert},
        connect_private_key: {key},
        enable_mtls: true,
        verify_name_on_connect: true,
      }},
    }},
  }},
}}
"#,
        ca = path("ca.pem"),
        cert = path(&format!("{name}.pem")),
        key = path(&format!("{name}.key")),
    )
}

/// The router's configuration: TLS only, clients must show a certificate
/// of the fleet's CA, and each robot reaches only its own key expressions.
fn router_config(address: &str, port: u16, robots: &[String]) -> String {
    let mut rules = vec![format!(
        r#"      {{ id: "master", messages: ["put", "declare_subscriber"], flows: ["ingress", "egress"], permission: "allow", key_exprs: ["twindrive/**"] }},"#
    )];
    let mut subjects = vec![format!(
        r#"      {{ id: "master", cert_common_names: ["{MASTER_CN}"] }},"#
    )];
    let mut policies = vec![r#"      { rules: ["master"], subjects: ["master"] },"#.to_string()];
    for id in robots {
        rules.push(format!(
            r#"      {{ id: "{id}-sends", messages: ["put"], flows: ["ingress"], permission: "allow", key_exprs: ["twindrive/{id}/down"] }},
      {{ id: "{id}-listens", messages: ["declare_subscriber"], flows: ["ingress"], permission: "allow", key_exprs: ["twindrive/{id}/up"] }},
      {{ id: "{id}-hears", messages: ["put"], flows: ["egress"], permission: "allow", key_exprs: ["twindrive/{id}/up"] }},
      {{ id: "{id}-heard", messages: ["declare_subscriber"], flows: ["egress"], permission: "allow", key_exprs: ["twindrive/{id}/down"] }},"#
        ));
        subjects.push(format!(
            r#"      {{ id: "{id}", cert_common_names: ["{id}"] }},"#
        ));
        policies.push(format!(
            r#"      {{ rules: ["{id}-sends", "{id}-listens", "{id}-hears", "{id}-heard"], subjects: ["{id}"] }},"#
        ));
    }
    format!(
        r#"// The fleet's zenoh router over TLS with mutual authentication and
// access control (written by `twindrive certs`): `twindrive router
// --zenoh-config router.json5` (or `zenohd -c router.json5`). A client
// without a certificate of this fleet's CA is refused; a robot may publish
// only on twindrive/ID/down and subscribe only to twindrive/ID/up; the
// master (common name {MASTER_CN}) reaches every robot's. File names are
// relative to this file's directory (`zenohd -c` reads them relative to
// where it runs: start it in this directory).
{{
  mode: "router",
  listen: {{ endpoints: ["tls/{address}:{port}"] }},
  scouting: {{ multicast: {{ enabled: false }} }},
  transport: {{
    link: {{
      tls: {{
        root_ca_certificate: {ca},
        listen_certificate: {cert},
        listen_private_key: {key},
        enable_mtls: true,
      }},
    }},
  }},
  access_control: {{
    enabled: true,
    default_permission: "deny",
    rules: [
{rules}
    ],
    subjects: [
{subjects}
    ],
    policies: [
{policies}
    ],
  }},
}}
"#,
        ca = path("ca.pem"),
        cert = path("router.pem"),
        key = path("router.key"),
        rules = rules.join("\n"),
        subjects = subjects.join("\n"),
        policies = policies.join("\n"),
    )
}
