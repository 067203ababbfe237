//! ROS 2 message definitions (`ros2msg`) as rosbag2 stores them in an MCAP
//! schema: the top-level type's `.msg` text, then every type it uses, each
//! after a line of `=` and a line `MSG: pkg/Type` (or `pkg/msg/Type`).
//!
//! [`Schema::parse`] resolves every nested type once, so decoding a message
//! ([`Schema::decode`](crate::Schema::decode)) and finding a field
//! ([`Schema::path`]) are index look-ups, not name look-ups.

use std::collections::HashMap;

/// A definition that cannot be used, with the type and line it is about.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{type_name}, line {line}: {message}")]
pub struct SchemaError {
    pub type_name: String,
    /// 1-based within that type's section; 0 when about the whole type.
    pub line: usize,
    pub message: String,
}

/// A CDR primitive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Primitive {
    Bool,
    /// `byte`: an octet.
    Byte,
    /// `char`: ROS 2 maps it to `uint8`.
    Char,
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Primitive {
    fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "bool" => Self::Bool,
            "byte" => Self::Byte,
            "char" => Self::Char,
            "int8" => Self::I8,
            "uint8" => Self::U8,
            "int16" => Self::I16,
            "uint16" => Self::U16,
            "int32" => Self::I32,
            "uint32" => Self::U32,
            "int64" => Self::I64,
            "uint64" => Self::U64,
            "float32" => Self::F32,
            "float64" => Self::F64,
            _ => return None,
        })
    }

    pub fn is_integer(self) -> bool {
        !matches!(self, Self::Bool | Self::F32 | Self::F64)
    }
}

/// The element type of a field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Base {
    Primitive(Primitive),
    String,
    WString,
    /// Index of a message type in the schema.
    Message(usize),
}

/// Single value, fixed array or sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arity {
    Single,
    Fixed(usize),
    /// `T[]` (no bound) or `T[<=N]`.
    Sequence(Option<usize>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FieldType {
    pub base: Base,
    pub arity: Arity,
    /// `N` of `string<=N` (the bytes on the wire are those of any string).
    pub string_bound: Option<usize>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    pub name: String,
    pub ty: FieldType,
}

/// One message type: its full name (`pkg/msg/Type`) and fields in order.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageType {
    pub name: String,
    pub fields: Vec<Field>,
}

/// A top-level type and every type it refers to, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct Schema {
    pub(crate) types: Vec<MessageType>,
}

/// Where a field sits: an index per level, from the top-level message down.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldPath {
    pub(crate) indices: Vec<usize>,
    pub ty: FieldType,
}

/// `pkg/Type`, `pkg/msg/Type` → `pkg/msg/Type`.
pub fn normalize_type_name(name: &str) -> String {
    let parts: Vec<&str> = name.split('/').collect();
    match parts[..] {
        [pkg, ty] => format!("{pkg}/msg/{ty}"),
        _ => name.to_string(),
    }
}

const SEPARATOR_MIN_EQUALS: usize = 3;

impl Schema {
    /// Parses `text` (a `ros2msg` schema) whose top-level type is `type_name`.
    pub fn parse(type_name: &str, text: &str) -> Result<Self, SchemaError> {
        let root = normalize_type_name(type_name);
        // Split into sections: the top-level one, then one per `MSG:` header.
        let mut sections: Vec<(String, Vec<&str>)> = vec![(root.clone(), Vec::new())];
        let mut lines = text.lines().peekable();
        while let Some(line) = lines.next() {
            let trimmed = line.trim();
            if trimmed.len() >= SEPARATOR_MIN_EQUALS && trimmed.bytes().all(|b| b == b'=') {
                let header = lines.next().map(str::trim).unwrap_or_default();
                let Some(name) = header.strip_prefix("MSG:") else {
                    return Err(SchemaError {
                        type_name: root,
                        line: 0,
                        message: format!(
                            "a line of `=` must be followed by `MSG: pkg/Type`, found `{header}`"
                        ),
                    });
                };
                sections.push((normalize_type_name(name.trim()), Vec::new()));
                continue;
            }
            sections.last_mut().expect("one section").1.push(line);
        }
        let index: HashMap<String, usize> = sections
            .iter()
            .enumerate()
            .map(|(i, (name, _))| (name.clone(), i))
            .collect();
        let mut types = Vec::with_capacity(sections.len());
        for (name, body) in &sections {
            let package = name.split('/').next().unwrap_or_default();
            let mut fields = Vec::new();
            for (k, raw) in body.iter().enumerate() {
                let err = |message: String| SchemaError {
                    type_name: name.clone(),
                    line: k + 1,
                    message,
                };
                let line = strip_comment(raw).trim();
                if line.is_empty() {
                    continue;
                }
                let mut words = line.split_whitespace();
                let ty_text = words.next().expect("non-empty");
                let rest = line[ty_text.len()..].trim_start();
                // A constant: `TYPE NAME=VALUE` (no field, nothing on the wire).
                let field_name: &str = rest
                    .split(|c: char| c.is_whitespace() || c == '=')
                    .next()
                    .unwrap_or_default();
                if field_name.is_empty() {
                    return Err(err(format!(
                        "expected `TYPE NAME`, found `{line}` (a field needs a name)"
                    )));
                }
                if rest[field_name.len()..].trim_start().starts_with('=') {
                    continue;
                }
                let ty = parse_type(ty_text, package, &index).map_err(err)?;
                fields.push(Field {
                    name: field_name.to_string(),
                    ty,
                });
            }
            types.push(MessageType {
                name: name.clone(),
                fields,
            });
        }
        let schema = Self { types };
        schema.check_acyclic()?;
        Ok(schema)
    }

    /// The integer fields that could carry encoder ticks, as `calibrate
    /// --left-field` takes them: `a.b` for a nested field, `data[0]` and
    /// `data[1]` for an integer array; header stamps left out.
    pub fn integer_fields(&self) -> Vec<String> {
        fn walk(s: &Schema, ty: usize, prefix: &str, depth: usize, out: &mut Vec<String>) {
            for f in &s.types[ty].fields {
                let name = format!("{prefix}{}", f.name);
                match (f.ty.base, f.ty.arity) {
                    (Base::Primitive(p), Arity::Single) if p.is_integer() => out.push(name),
                    (Base::Primitive(p), _) if p.is_integer() && p != Primitive::U8 => {
                        out.push(format!("{name}[0]"));
                        out.push(format!("{name}[1]"));
                    }
                    (Base::Message(m), Arity::Single)
                        if depth < 3 && s.types[m].name != "std_msgs/msg/Header" =>
                    {
                        walk(s, m, &format!("{name}."), depth + 1, out)
                    }
                    _ => {}
                }
            }
        }
        let mut out = Vec::new();
        walk(self, 0, "", 0, &mut out);
        out
    }

    /// The top-level type.
    pub fn root(&self) -> &MessageType {
        &self.types[0]
    }

    pub fn type_at(&self, index: usize) -> &MessageType {
        &self.types[index]
    }

    /// Resolves a dotted path such as `header.stamp.sec` or `pose.pose.position.x`.
    pub fn path(&self, dotted: &str) -> Result<FieldPath, String> {
        self.path_from(0, dotted)
    }

    /// Resolves a dotted path inside type `ty` (an element of a message
    /// array, such as one `TransformStamped` of a `TFMessage`); the path
    /// applies to that element's [`Value`](crate::Value).
    pub fn path_from(&self, ty: usize, dotted: &str) -> Result<FieldPath, String> {
        let mut ty = ty;
        let mut indices = Vec::new();
        let mut last = None;
        for (depth, part) in dotted.split('.').enumerate() {
            if let Some(FieldType {
                base: Base::Message(next),
                arity: Arity::Single,
                ..
            }) = last
            {
                ty = next;
            } else if depth > 0 {
                return Err(format!(
                    "`{dotted}`: `{}` is not a message, so it has no field `{part}`",
                    dotted.split('.').take(depth).collect::<Vec<_>>().join(".")
                ));
            }
            let t = &self.types[ty];
            let Some(i) = t.fields.iter().position(|f| f.name == part) else {
                return Err(format!(
                    "`{dotted}`: {} has no field `{part}` (it has: {})",
                    t.name,
                    t.fields
                        .iter()
                        .map(|f| f.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            };
            indices.push(i);
            last = Some(t.fields[i].ty);
        }
        Ok(FieldPath {
            indices,
            ty: last.ok_or_else(|| "an empty field path".to_string())?,
        })
    }

    fn check_acyclic(&self) -> Result<(), SchemaError> {
        // Depth-first with colours: a type that contains itself cannot be decoded.
        fn visit(s: &Schema, t: usize, colour: &mut [u8]) -> Result<(), SchemaError> {
            match colour[t] {
                1 => {
                    return Err(SchemaError {
                        type_name: s.types[t].name.clone(),
                        line: 0,
                        message: "the type contains itself".into(),
                    });
                }
                2 => return Ok(()),
                _ => {}
            }
            colour[t] = 1;
            for f in &s.types[t].fields {
                if let Base::Message(n) = f.ty.base {
                    visit(s, n, colour)?;
                }
            }
            colour[t] = 2;
            Ok(())
        }
        visit(self, 0, &mut vec![0; self.types.len()])
    }
}

/// Removes a `#` comment, except inside a quoted string default or constant.
fn strip_comment(line: &str) -> &str {
    let mut quote = None;
    for (i, c) in line.char_indices() {
        match (quote, c) {
            (None, '#') => return &line[..i],
            (None, '"' | '\'') => quote = Some(c),
            (Some(q), c) if c == q => quote = None,
            _ => {}
        }
    }
    line
}

fn parse_type(
    text: &str,
    package: &str,
    index: &HashMap<String, usize>,
) -> Result<FieldType, String> {
    let (element, arity) = match text.find('[') {
        None => (text, Arity::Single),
        Some(open) => {
            let inner = text[open + 1..]
                .strip_suffix(']')
                .ok_or_else(|| format!("`{text}`: an array type ends with `]`"))?;
            let arity = if inner.is_empty() {
                Arity::Sequence(None)
            } else if let Some(bound) = inner.strip_prefix("<=") {
                Arity::Sequence(Some(bound.parse().map_err(|_| {
                    format!("`{text}`: the bound `{bound}` is not a whole number")
                })?))
            } else {
                Arity::Fixed(inner.parse().map_err(|_| {
                    format!("`{text}`: the array size `{inner}` is not a whole number")
                })?)
            };
            (&text[..open], arity)
        }
    };
    // `string<=N` bounds only limit the length; they do not change the bytes.
    let (element, string_bound) = match element.split_once("<=") {
        Some((e, bound)) => (
            e,
            Some(bound.parse::<usize>().map_err(|_| {
                format!("`{text}`: the string bound `{bound}` is not a whole number")
            })?),
        ),
        None => (element, None),
    };
    let base = if let Some(p) = Primitive::from_name(element) {
        Base::Primitive(p)
    } else if element == "string" {
        Base::String
    } else if element == "wstring" {
        Base::WString
    } else {
        let full = if element.contains('/') {
            normalize_type_name(element)
        } else if element == "Header" {
            "std_msgs/msg/Header".to_string()
        } else {
            format!("{package}/msg/{element}")
        };
        Base::Message(*index.get(&full).ok_or_else(|| {
            format!("the type `{element}` is neither a primitive nor defined in the schema (no `MSG: {full}` section)")
        })?)
    };
    if string_bound.is_some() && !matches!(base, Base::String | Base::WString) {
        return Err(format!("`{text}`: only strings take a `<=N` length bound"));
    }
    Ok(FieldType {
        base,
        arity,
        string_bound,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const POSE_STAMPED: &str = "\
# A Pose with reference coordinate frame and timestamp

std_msgs/Header header
Pose pose

================================================================================
MSG: std_msgs/Header
# Standard metadata for higher-level stamped data types.
builtin_interfaces/Time stamp
string frame_id # with a comment

================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec

================================================================================
MSG: geometry_msgs/Pose
Point position
Quaternion orientation

================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z

================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
uint8 FOO=3 # a constant
string BAR=\"a # not a comment\"
";

    #[test]
    fn nested_types_resolve_and_paths_find_fields() {
        let s = Schema::parse("geometry_msgs/msg/PoseStamped", POSE_STAMPED).unwrap();
        assert_eq!(s.root().name, "geometry_msgs/msg/PoseStamped");
        assert_eq!(s.types.len(), 6);
        let q = s
            .types
            .iter()
            .find(|t| t.name.ends_with("Quaternion"))
            .unwrap();
        assert_eq!(q.fields.len(), 4, "constants are not fields");
        let p = s.path("pose.position.y").unwrap();
        assert_eq!(p.indices, vec![1, 0, 1]);
        assert_eq!(p.ty.base, Base::Primitive(Primitive::F64));
        let stamp = s.path("header.stamp.nanosec").unwrap();
        assert_eq!(stamp.ty.base, Base::Primitive(Primitive::U32));
        let e = s.path("pose.velocity").unwrap_err();
        assert!(
            e.contains("has no field `velocity`") && e.contains("position"),
            "{e}"
        );
        let e = s.path("pose.position.x.y").unwrap_err();
        assert!(e.contains("is not a message"), "{e}");
    }

    #[test]
    fn arrays_and_bounds() {
        let s = Schema::parse(
            "pkg/msg/A",
            "float64[9] cov\nint32[] seq\nstring<=8[<=3] names\nuint8[<=4] b\n",
        )
        .unwrap();
        let f: Vec<Arity> = s.root().fields.iter().map(|f| f.ty.arity).collect();
        assert_eq!(
            f,
            vec![
                Arity::Fixed(9),
                Arity::Sequence(None),
                Arity::Sequence(Some(3)),
                Arity::Sequence(Some(4))
            ]
        );
        assert_eq!(s.root().fields[2].ty.base, Base::String);
    }

    #[test]
    fn unknown_types_and_bad_lines_name_type_and_line() {
        let e = Schema::parse("pkg/msg/A", "int32 a\nFoo b\n").unwrap_err();
        assert_eq!((e.type_name.as_str(), e.line), ("pkg/msg/A", 2));
        assert!(
            e.message.contains("`Foo`") && e.message.contains("MSG: pkg/msg/Foo"),
            "{e}"
        );
        let e = Schema::parse("pkg/msg/A", "int32[x] a\n").unwrap_err();
        assert!(e.message.contains("not a whole number"), "{e}");
        let e = Schema::parse("pkg/msg/A", "int32\n").unwrap_err();
        assert!(e.message.contains("needs a name"), "{e}");
        let e = Schema::parse("pkg/msg/A", "B b\n===\nMSG: pkg/B\nA a\n").unwrap_err();
        assert!(e.message.contains("contains itself"), "{e}");
    }
}
