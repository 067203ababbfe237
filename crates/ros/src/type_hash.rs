//! RIHS01 type hashes (REP-2011): what ROS 2 from Iron on, and rmw_zenoh's
//! key expressions and liveliness tokens, use to tell message types apart.
//!
//! The hash is SHA-256 over a JSON text of the type's description: its
//! name and fields (each with a numeric type id, capacities and the nested
//! type's name), then every type it refers to, sorted by name; default
//! values left out; Python `json.dumps` spacing (`", "` and `": "`), as
//! `rosidl_generator_type_description` writes it.

use std::collections::BTreeSet;
use std::fmt::Write;

use sha2::{Digest, Sha256};

use crate::schema::{Arity, Base, FieldType, Primitive, Schema};

/// `type_description_interfaces/msg/FieldType` ids of the element types.
fn element_id(ty: &FieldType) -> u8 {
    match ty.base {
        Base::Message(_) => 1,
        Base::Primitive(p) => match p {
            Primitive::I8 => 2,
            // `.msg` `char` becomes IDL `uint8`.
            Primitive::U8 | Primitive::Char => 3,
            Primitive::I16 => 4,
            Primitive::U16 => 5,
            Primitive::I32 => 6,
            Primitive::U32 => 7,
            Primitive::I64 => 8,
            Primitive::U64 => 9,
            Primitive::F32 => 10,
            Primitive::F64 => 11,
            Primitive::Bool => 15,
            Primitive::Byte => 16,
        },
        Base::String if ty.string_bound.is_some() => 21,
        Base::String => 17,
        Base::WString if ty.string_bound.is_some() => 22,
        Base::WString => 18,
    }
}

fn field_json(out: &mut String, schema: &Schema, name: &str, ty: &FieldType) {
    let (offset, capacity) = match ty.arity {
        Arity::Single => (0, 0),
        Arity::Fixed(n) => (48, n),
        Arity::Sequence(Some(n)) => (96, n),
        Arity::Sequence(None) => (144, 0),
    };
    let nested = match ty.base {
        Base::Message(t) => schema.type_at(t).name.as_str(),
        _ => "",
    };
    let _ = write!(
        out,
        "{{\"name\": \"{name}\", \"type\": {{\"type_id\": {}, \"capacity\": {capacity}, \"string_capacity\": {}, \"nested_type_name\": \"{nested}\"}}}}",
        u32::from(element_id(ty)) + offset,
        ty.string_bound.unwrap_or(0),
    );
}

fn type_json(out: &mut String, schema: &Schema, index: usize) {
    let t = schema.type_at(index);
    let _ = write!(out, "{{\"type_name\": \"{}\", \"fields\": [", t.name);
    if t.fields.is_empty() {
        // IDL gives an empty message one placeholder member.
        let placeholder = FieldType {
            base: Base::Primitive(Primitive::U8),
            arity: Arity::Single,
            string_bound: None,
        };
        field_json(
            out,
            schema,
            "structure_needs_at_least_one_member",
            &placeholder,
        );
    }
    for (i, f) in t.fields.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        field_json(out, schema, &f.name, &f.ty);
    }
    out.push_str("]}");
}

impl Schema {
    /// The canonical JSON text the hash is taken over.
    pub fn type_description_json(&self) -> String {
        // Every type reachable from the top-level one, by name.
        let mut reachable = BTreeSet::new();
        let mut stack = vec![0usize];
        while let Some(t) = stack.pop() {
            for f in &self.type_at(t).fields {
                if let Base::Message(n) = f.ty.base
                    && reachable.insert((self.type_at(n).name.clone(), n))
                {
                    stack.push(n);
                }
            }
        }
        let mut out = String::from("{\"type_description\": ");
        type_json(&mut out, self, 0);
        out.push_str(", \"referenced_type_descriptions\": [");
        for (i, (_, t)) in reachable.iter().enumerate() {
            if i > 0 {
                out.push_str(", ");
            }
            type_json(&mut out, self, *t);
        }
        out.push_str("]}");
        out
    }

    /// `RIHS01_<64 lowercase hex digits>`.
    pub fn type_hash(&self) -> String {
        let digest = Sha256::digest(self.type_description_json().as_bytes());
        let mut out = String::from("RIHS01_");
        for b in digest {
            let _ = write!(out, "{b:02x}");
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use crate::Schema;
    use crate::msgs::{Distro, definition};

    /// Hashes published by ROS 2 itself: rmw_zenoh's design document
    /// (`std_msgs/msg/String`), and the `*__description.c` files and key
    /// expressions rosidl generates for Jazzy.
    #[test]
    fn hashes_match_the_ones_ros_publishes() {
        for (t, expected) in [
            (
                "std_msgs/msg/String",
                "df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
            ),
            (
                "std_msgs/msg/Header",
                "f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
            ),
            (
                "builtin_interfaces/msg/Time",
                "b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197",
            ),
            (
                "geometry_msgs/msg/Point",
                "6963084842a9b04494d6b2941d11444708d892da2f4b09843b9c43f42a7f6881",
            ),
            (
                "geometry_msgs/msg/Twist",
                "9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
            ),
            (
                "nav_msgs/msg/Odometry",
                "3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
            ),
        ] {
            assert_eq!(
                crate::msgs::type_hash(t).unwrap(),
                format!("RIHS01_{expected}"),
                "{t}"
            );
        }
    }

    #[test]
    fn the_json_has_python_spacing_and_sorted_references() {
        let s = Schema::parse(
            "std_msgs/msg/Header",
            &definition("std_msgs/msg/Header", Distro::Jazzy).unwrap(),
        )
        .unwrap();
        assert_eq!(
            s.type_description_json(),
            "{\"type_description\": {\"type_name\": \"std_msgs/msg/Header\", \"fields\": [\
             {\"name\": \"stamp\", \"type\": {\"type_id\": 1, \"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"builtin_interfaces/msg/Time\"}}, \
             {\"name\": \"frame_id\", \"type\": {\"type_id\": 17, \"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"\"}}]}, \
             \"referenced_type_descriptions\": [{\"type_name\": \"builtin_interfaces/msg/Time\", \"fields\": [\
             {\"name\": \"sec\", \"type\": {\"type_id\": 6, \"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"\"}}, \
             {\"name\": \"nanosec\", \"type\": {\"type_id\": 7, \"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"\"}}]}]}"
        );
        let arrays = Schema::parse(
            "p/msg/A",
            "float64[36] c\nstring<=5[<=3] s\nint8[] d\nbyte b\nchar c2\n",
        )
        .unwrap();
        let j = arrays.type_description_json();
        for part in [
            "\"type_id\": 59, \"capacity\": 36",
            "\"type_id\": 117, \"capacity\": 3, \"string_capacity\": 5",
            "\"type_id\": 146, \"capacity\": 0",
            "\"name\": \"b\", \"type\": {\"type_id\": 16",
            "\"name\": \"c2\", \"type\": {\"type_id\": 3",
        ] {
            assert!(j.contains(part), "{part} in {j}");
        }
    }
}
