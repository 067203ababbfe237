//! What `rmw_zenoh` (ROS 2's zenoh middleware, Jazzy on) puts on a zenoh
//! network, as strings and bytes: topic key expressions, liveliness tokens
//! (how `ros2 topic list` and `ros2 node list` find entities), the QoS part
//! of a token, and the attachment every sample carries. No zenoh here: the
//! network code uses these.
//!
//! - Topic data: `<domain>/<topic without its leading slash>/<pkg>::msg::dds_::<Type>_/<RIHS01 hash>`.
//! - Liveliness: `@ros2_lv/<domain>/<zenoh id>/<node id>/<entity id>/<NN|MP|MS>/<enclave>/<namespace>/<node>`
//!   and, for publishers and subscriptions, `/<topic>/<type>/<hash>/<qos>`, every `/` inside a
//!   name replaced by `%` and an empty name written `%`.
//! - Attachment: sequence number (i64 LE, from 1), source time (i64 LE, ns
//!   since the Unix epoch), the publisher's 16-byte GID after its LEB128
//!   length (one byte, 16): 33 bytes.

pub use crate::qos::Qos;

/// `pkg/msg/Type` → `pkg::msg::dds_::Type_`.
pub fn dds_type_name(type_name: &str) -> String {
    let parts: Vec<&str> = type_name.split('/').collect();
    match parts[..] {
        [pkg, kind, name] => format!("{pkg}::{kind}::dds_::{name}_"),
        [pkg, name] => format!("{pkg}::msg::dds_::{name}_"),
        _ => type_name.replace('/', "::"),
    }
}

/// A ROS name (`/ns/topic`) with every `/` as `%`; empty or `/` is `%`.
pub fn mangle(name: &str) -> String {
    if name.is_empty() || name == "/" {
        "%".into()
    } else {
        name.replace('/', "%")
    }
}

/// `/` + `name` made absolute under `namespace` (`cmd_vel` in `/tb3` is
/// `/tb3/cmd_vel`; an absolute name stays as it is).
pub fn fully_qualified(namespace: &str, name: &str) -> String {
    if name.starts_with('/') {
        return name.to_string();
    }
    let ns = namespace.trim_end_matches('/');
    if ns.is_empty() {
        format!("/{name}")
    } else if ns.starts_with('/') {
        format!("{ns}/{name}")
    } else {
        format!("/{ns}/{name}")
    }
}

/// The type hash of a message type twindrive knows (Jazzy definitions).
pub use crate::msgs::type_hash;

/// The data key expression of `topic` (fully qualified) with type `type_name`.
pub fn topic_key(domain_id: u32, topic: &str, type_name: &str, hash: &str) -> String {
    let name = topic.strip_prefix('/').unwrap_or(topic);
    let name = name.strip_suffix('/').unwrap_or(name);
    format!("{domain_id}/{name}/{}/{hash}", dds_type_name(type_name))
}

/// The key expression that matches `topic` of `type_name` with any hash
/// (a robot on another distribution, or a type revised since).
pub fn topic_key_any_hash(domain_id: u32, topic: &str, type_name: &str) -> String {
    topic_key(domain_id, topic, type_name, "*")
}

/// What a liveliness token announces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Entity<'a> {
    Node,
    Publisher {
        topic: &'a str,
        type_name: &'a str,
        hash: &'a str,
        qos: Qos,
    },
    Subscription {
        topic: &'a str,
        type_name: &'a str,
        hash: &'a str,
        qos: Qos,
    },
}

/// The node an entity belongs to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeId<'a> {
    pub domain_id: u32,
    /// The zenoh session's id as its `Display` writes it.
    pub zid: &'a str,
    pub node_id: u32,
    pub namespace: &'a str,
    pub name: &'a str,
}

/// The liveliness token of entity `entity_id` of `node`.
pub fn liveliness_token(node: &NodeId<'_>, entity_id: u32, entity: Entity<'_>) -> String {
    let (kind, rest) = match entity {
        Entity::Node => ("NN", None),
        Entity::Publisher {
            topic,
            type_name,
            hash,
            qos,
        } => ("MP", Some((topic, type_name, hash, qos))),
        Entity::Subscription {
            topic,
            type_name,
            hash,
            qos,
        } => ("MS", Some((topic, type_name, hash, qos))),
    };
    let mut token = format!(
        "@ros2_lv/{}/{}/{}/{}/{kind}/%/{}/{}",
        node.domain_id,
        node.zid,
        node.node_id,
        entity_id,
        mangle(node.namespace),
        mangle(node.name)
    );
    if let Some((topic, type_name, hash, qos)) = rest {
        token.push_str(&format!(
            "/{}/{}/{}/{}",
            mangle(topic),
            mangle(&dds_type_name(type_name)),
            mangle(hash),
            qos.keyexpr()
        ));
    }
    token
}

/// A publisher's GID: the XXH3-128 of its liveliness token, low half first.
pub fn gid(token: &str) -> [u8; 16] {
    let h = xxhash_rust::xxh3::xxh3_128(token.as_bytes());
    let mut out = [0u8; 16];
    out[..8].copy_from_slice(&(h as u64).to_le_bytes());
    out[8..].copy_from_slice(&((h >> 64) as u64).to_le_bytes());
    out
}

/// The metadata every rmw_zenoh sample carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    pub sequence_number: i64,
    pub source_timestamp_ns: i64,
    pub gid: [u8; 16],
}

impl Attachment {
    pub const LEN: usize = 33;

    pub fn encode(&self) -> [u8; Self::LEN] {
        let mut out = [0u8; Self::LEN];
        out[..8].copy_from_slice(&self.sequence_number.to_le_bytes());
        out[8..16].copy_from_slice(&self.source_timestamp_ns.to_le_bytes());
        out[16] = 16;
        out[17..].copy_from_slice(&self.gid);
        out
    }

    pub fn decode(bytes: &[u8]) -> Result<Self, String> {
        if bytes.len() != Self::LEN || bytes[16] != 16 {
            return Err(format!(
                "an rmw_zenoh attachment is {} bytes with a GID length of 16; got {} bytes",
                Self::LEN,
                bytes.len()
            ));
        }
        let i64_at = |i: usize| i64::from_le_bytes(bytes[i..i + 8].try_into().expect("8 bytes"));
        Ok(Self {
            sequence_number: i64_at(0),
            source_timestamp_ns: i64_at(8),
            gid: bytes[17..].try_into().expect("16 bytes"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STRING_HASH: &str =
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";

    /// The examples in rmw_zenoh's `docs/design.md`.
    #[test]
    fn keys_and_tokens_match_the_design_document() {
        assert_eq!(type_hash("std_msgs/msg/String").unwrap(), STRING_HASH);
        assert_eq!(
            topic_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH),
            format!("0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
        );
        assert_eq!(
            topic_key(0, "/robot1/chatter", "std_msgs/msg/String", STRING_HASH),
            format!("0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
        );
        let listener = NodeId {
            domain_id: 0,
            zid: "aac3178e146ba6f1fc6e6a4085e77f21",
            node_id: 0,
            namespace: "/",
            name: "listener",
        };
        assert_eq!(
            liveliness_token(&listener, 0, Entity::Node),
            "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
        );
        assert_eq!(
            liveliness_token(
                &listener,
                10,
                Entity::Subscription {
                    topic: "/chatter",
                    type_name: "std_msgs/msg/String",
                    hash: STRING_HASH,
                    qos: Qos::DEFAULT,
                }
            ),
            format!(
                "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,"
            )
        );
        let talker = NodeId {
            zid: "8b20917502ee955ac4476e0266340d5c",
            name: "talker",
            ..listener
        };
        let qos = Qos {
            depth: 7,
            ..Qos::DEFAULT
        };
        assert_eq!(
            liveliness_token(
                &talker,
                10,
                Entity::Publisher {
                    topic: "/chatter",
                    type_name: "std_msgs/msg/String",
                    hash: STRING_HASH,
                    qos,
                }
            ),
            format!(
                "@ros2_lv/0/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,"
            )
        );
        assert_eq!(Qos::SENSOR_DATA.keyexpr(), "2::,5:,:,:,,");
    }

    #[test]
    fn names_qualify_and_mangle() {
        assert_eq!(fully_qualified("", "cmd_vel"), "/cmd_vel");
        assert_eq!(fully_qualified("/tb3", "cmd_vel"), "/tb3/cmd_vel");
        assert_eq!(fully_qualified("tb3/", "cmd_vel"), "/tb3/cmd_vel");
        assert_eq!(fully_qualified("/tb3", "/cmd_vel"), "/cmd_vel");
        assert_eq!(mangle("/tb3/cmd_vel"), "%tb3%cmd_vel");
        assert_eq!(mangle(""), "%");
        assert_eq!(
            dds_type_name("geometry_msgs/msg/Twist"),
            "geometry_msgs::msg::dds_::Twist_"
        );
    }

    #[test]
    fn attachments_round_trip_and_refuse_other_layouts() {
        let a = Attachment {
            sequence_number: 1,
            source_timestamp_ns: 1_700_000_000_123_456_789,
            gid: gid("@ros2_lv/0/x/0/1/MP/%/%/n/%t/T/H/::,10:,:,:,,"),
        };
        let bytes = a.encode();
        assert_eq!(bytes.len(), 33);
        assert_eq!(&bytes[..8], &1i64.to_le_bytes());
        assert_eq!(bytes[16], 16);
        assert_eq!(Attachment::decode(&bytes).unwrap(), a);
        assert!(Attachment::decode(&bytes[..32]).is_err());
        assert_ne!(a.gid, gid("another token"));
    }
}
