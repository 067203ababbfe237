//! Decoding CDR bytes with a [`Schema`] read at run time.
//!
//! The primitives, alignment and lengths are read by `cdr-encoding` (the
//! CDR implementation of RustDDS and ros2-client); this module walks the
//! schema and builds a [`Value`].

use byteorder::{BigEndian, ByteOrder, LittleEndian};
use cdr_encoding::CdrDeserializer;
use serde::Deserialize;

use crate::schema::{Arity, Base, FieldPath, Primitive, Schema};

/// A decoded message field.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Bool(bool),
    Int(i64),
    UInt(u64),
    Float(f64),
    String(String),
    /// A `uint8`/`byte` array or sequence.
    Bytes(Vec<u8>),
    Array(Vec<Value>),
    /// A nested message: its fields in schema order.
    Message(Vec<Value>),
}

impl Value {
    /// The field at `path` (from [`Schema::path`]) of this top-level message.
    pub fn at(&self, path: &FieldPath) -> Option<&Value> {
        let mut v = self;
        for &i in &path.indices {
            match v {
                Value::Message(fields) => v = fields.get(i)?,
                _ => return None,
            }
        }
        Some(v)
    }

    /// Any number as f64 (integers convert exactly below 2⁵³).
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Value::Int(i) => Some(i as f64),
            Value::UInt(u) => Some(u as f64),
            Value::Float(f) => Some(f),
            _ => None,
        }
    }

    /// An integer as i64.
    pub fn as_i64(&self) -> Option<i64> {
        match *self {
            Value::Int(i) => Some(i),
            Value::UInt(u) => i64::try_from(u).ok(),
            _ => None,
        }
    }

    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::String(s) => Some(s),
            _ => None,
        }
    }

    /// The elements of an array or sequence.
    pub fn as_array(&self) -> Option<&[Value]> {
        match self {
            Value::Array(a) => Some(a),
            _ => None,
        }
    }

    pub fn as_message(&self) -> Option<&[Value]> {
        match self {
            Value::Message(m) => Some(m),
            _ => None,
        }
    }
}

/// Why a message's bytes do not match its definition.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct DecodeError {
    pub message: String,
}

fn fail<T>(message: impl Into<String>) -> Result<T, DecodeError> {
    Err(DecodeError {
        message: message.into(),
    })
}

/// Longest sequence accepted (elements): a corrupt length must not make the
/// decoder reserve gigabytes.
const MAX_SEQUENCE: usize = 1 << 28;

/// Bytes a serializer may add after the last field to round the message up.
const MAX_TRAILING_PADDING: usize = 7;

impl Schema {
    /// Decodes one serialized message (with its 4-byte encapsulation header).
    pub fn decode(&self, bytes: &[u8]) -> Result<Value, DecodeError> {
        if bytes.len() < 4 {
            return fail(format!(
                "{} bytes is too short for a CDR encapsulation header (4 bytes)",
                bytes.len()
            ));
        }
        let body = &bytes[4..];
        let (value, used) = match [bytes[0], bytes[1]] {
            [0, 0] => self.decode_body::<BigEndian>(body)?,
            [0, 1] => self.decode_body::<LittleEndian>(body)?,
            id => {
                return fail(format!(
                    "encapsulation {:#06x} is not plain CDR (0x0000 big-endian or 0x0001 little-endian); \
                     XCDR2 and parameter lists are not supported",
                    u16::from_be_bytes(id)
                ));
            }
        };
        let extra = body.len() - used;
        if extra > MAX_TRAILING_PADDING {
            return fail(format!(
                "{extra} bytes are left after the last field of {}: the bytes were written with another definition",
                self.root().name
            ));
        }
        Ok(value)
    }

    fn decode_body<BO: ByteOrder>(&self, body: &[u8]) -> Result<(Value, usize), DecodeError> {
        let mut de = CdrDeserializer::<BO>::new(body);
        let v = self.message(0, &mut de)?;
        Ok((v, de.bytes_consumed()))
    }

    fn message<BO: ByteOrder>(
        &self,
        ty: usize,
        de: &mut CdrDeserializer<'_, BO>,
    ) -> Result<Value, DecodeError> {
        let t = &self.types[ty];
        if t.fields.is_empty() {
            // An empty ROS 2 message is one placeholder byte on the wire.
            read::<u8, BO>(de, &t.name)?;
            return Ok(Value::Message(Vec::new()));
        }
        let mut out = Vec::with_capacity(t.fields.len());
        for f in &t.fields {
            let v = match f.ty.arity {
                Arity::Single => self.element(f.ty.base, de),
                Arity::Fixed(n) => self.elements(f.ty.base, n, de),
                Arity::Sequence(bound) => {
                    let n = read::<u32, BO>(de, "a sequence length")? as usize;
                    if n > MAX_SEQUENCE || bound.is_some_and(|b| n > b) {
                        fail(format!(
                            "a sequence of {n} elements{}",
                            bound.map_or(" is implausible".into(), |b| format!(
                                " exceeds its bound {b}"
                            ))
                        ))
                    } else {
                        self.elements(f.ty.base, n, de)
                    }
                }
            }
            .map_err(|e| DecodeError {
                message: format!("field `{}` of {}: {}", f.name, t.name, e.message),
            })?;
            out.push(v);
        }
        Ok(Value::Message(out))
    }

    fn elements<BO: ByteOrder>(
        &self,
        base: Base,
        n: usize,
        de: &mut CdrDeserializer<'_, BO>,
    ) -> Result<Value, DecodeError> {
        if let Base::Primitive(Primitive::U8 | Primitive::Byte | Primitive::Char) = base {
            let mut bytes = Vec::with_capacity(n.min(1 << 20));
            for _ in 0..n {
                bytes.push(read::<u8, BO>(de, "a byte")?);
            }
            return Ok(Value::Bytes(bytes));
        }
        let mut out = Vec::with_capacity(n.min(1 << 16));
        for _ in 0..n {
            out.push(self.element(base, de)?);
        }
        Ok(Value::Array(out))
    }

    fn element<BO: ByteOrder>(
        &self,
        base: Base,
        de: &mut CdrDeserializer<'_, BO>,
    ) -> Result<Value, DecodeError> {
        use Primitive as P;
        Ok(match base {
            Base::Primitive(p) => match p {
                P::Bool => Value::Bool(read::<bool, BO>(de, "a bool")?),
                P::Byte | P::Char | P::U8 => Value::UInt(read::<u8, BO>(de, "a uint8")?.into()),
                P::I8 => Value::Int(read::<i8, BO>(de, "an int8")?.into()),
                P::I16 => Value::Int(read::<i16, BO>(de, "an int16")?.into()),
                P::U16 => Value::UInt(read::<u16, BO>(de, "a uint16")?.into()),
                P::I32 => Value::Int(read::<i32, BO>(de, "an int32")?.into()),
                P::U32 => Value::UInt(read::<u32, BO>(de, "a uint32")?.into()),
                P::I64 => Value::Int(read::<i64, BO>(de, "an int64")?),
                P::U64 => Value::UInt(read::<u64, BO>(de, "a uint64")?),
                P::F32 => Value::Float(read::<f32, BO>(de, "a float32")?.into()),
                P::F64 => Value::Float(read::<f64, BO>(de, "a float64")?),
            },
            Base::String => Value::String(read::<String, BO>(de, "a string")?),
            Base::WString => return fail("wstring fields are not supported"),
            Base::Message(t) => self.message(t, de)?,
        })
    }
}

fn read<'de, T: Deserialize<'de>, BO: ByteOrder>(
    de: &mut CdrDeserializer<'de, BO>,
    what: &str,
) -> Result<T, DecodeError> {
    T::deserialize(de).map_err(|e| DecodeError {
        message: match e {
            cdr_encoding::Error::Eof => format!("the message ends before {what}"),
            e => format!("{what}: {e}"),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schema() -> Schema {
        Schema::parse(
            "pkg/msg/A",
            "uint8 flag\nfloat64 x\nstring name\nint16[] vals\nuint8[] raw\nB[2] bs\nE e\n\
             ===\nMSG: pkg/B\nint32 k\n===\nMSG: pkg/E\n",
        )
        .unwrap()
    }

    #[test]
    fn decodes_little_and_big_endian_with_alignment() {
        // flag=7, pad to 8, x=1.5, name="ab", vals=[-1,2], raw=[9], bs=[{3},{4}], e={}.
        let mut le = vec![0, 1, 0, 0, 7, 0, 0, 0, 0, 0, 0, 0];
        le.extend(1.5f64.to_le_bytes());
        le.extend(3u32.to_le_bytes());
        le.extend(b"ab\0\0");
        le.extend(2u32.to_le_bytes());
        le.extend((-1i16).to_le_bytes());
        le.extend(2i16.to_le_bytes());
        le.extend(1u32.to_le_bytes());
        le.extend([9, 0, 0, 0]);
        le.extend(3i32.to_le_bytes());
        le.extend(4i32.to_le_bytes());
        le.push(0);
        let s = schema();
        let v = s.decode(&le).unwrap();
        let expected = Value::Message(vec![
            Value::UInt(7),
            Value::Float(1.5),
            Value::String("ab".into()),
            Value::Array(vec![Value::Int(-1), Value::Int(2)]),
            Value::Bytes(vec![9]),
            Value::Array(vec![
                Value::Message(vec![Value::Int(3)]),
                Value::Message(vec![Value::Int(4)]),
            ]),
            Value::Message(vec![]),
        ]);
        assert_eq!(v, expected);
        assert_eq!(v.at(&s.path("x").unwrap()).unwrap().as_f64(), Some(1.5));

        let mut be = vec![0, 0, 0, 0, 7, 0, 0, 0, 0, 0, 0, 0];
        be.extend(1.5f64.to_be_bytes());
        be.extend(3u32.to_be_bytes());
        be.extend(b"ab\0\0");
        be.extend(2u32.to_be_bytes());
        be.extend((-1i16).to_be_bytes());
        be.extend(2i16.to_be_bytes());
        be.extend(1u32.to_be_bytes());
        be.extend([9, 0, 0, 0]);
        be.extend(3i32.to_be_bytes());
        be.extend(4i32.to_be_bytes());
        be.push(0);
        assert_eq!(s.decode(&be).unwrap(), expected);
    }

    #[test]
    fn truncated_and_foreign_bytes_say_where() {
        let s = schema();
        let e = s.decode(&[0, 1, 0, 0, 7, 0, 0, 0, 1, 2]).unwrap_err();
        assert!(
            e.message.contains("field `x`") && e.message.contains("ends before a float64"),
            "{e}"
        );
        let e = s.decode(&[0, 7, 0, 0, 1]).unwrap_err();
        assert!(e.message.contains("0x0007 is not plain CDR"), "{e}");
        let mut huge = vec![0, 1, 0, 0, 7, 0, 0, 0, 0, 0, 0, 0];
        huge.extend(1.5f64.to_le_bytes());
        huge.extend(1u32.to_le_bytes());
        huge.extend([0, 0, 0, 0]);
        huge.extend(u32::MAX.to_le_bytes());
        let e = s.decode(&huge).unwrap_err();
        assert!(e.message.contains("implausible"), "{e}");
        let b = Schema::parse("pkg/msg/B", "int32 k\n").unwrap();
        let e = b
            .decode(&[0, 1, 0, 0, 1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8])
            .unwrap_err();
        assert!(e.message.contains("another definition"), "{e}");
    }
}
