//! ROS 2 without a ROS install.
//!
//! ROS 2 messages are CDR bytes described by `.msg` definitions, and rosbag2
//! recordings are MCAP files or sqlite3 databases that hold those bytes
//! (and, mostly, the definitions). This crate reads both at run time
//! ([`Schema`], [`Value`], [`Bag`]) and writes the standard messages
//! twindrive produces ([`msgs`], [`BagWriter`]).

pub mod bag;
pub mod export;
pub mod extract;
pub mod live;
pub mod msgs;
mod qos;
pub mod rmw_zenoh;
mod schema;
mod type_hash;
pub mod urdf;
mod value;

pub use bag::{
    Bag, BagError, BagWriter, Damage, FileInfo, MessageRef, Metadata, Storage, TopicId, TopicInfo,
    WriteError,
};
pub use msgs::{Distro, RosMessage};
pub use qos::Qos;
pub use schema::{
    Arity, Base, Field, FieldPath, FieldType, MessageType, Primitive, Schema, SchemaError,
    normalize_type_name,
};
pub use value::{DecodeError, Value};
