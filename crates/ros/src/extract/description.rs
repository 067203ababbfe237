//! The robot's description as `robot_state_publisher` publishes it: a
//! `std_msgs/msg/String` holding the URDF, on `/robot_description` (or a
//! namespaced `/NS/robot_description`), latched (one message, recorded
//! once).

use super::{topic_error, typed_schema};
use crate::bag::{Bag, BagError};
use crate::schema::normalize_type_name;

/// The standard topic.
pub const ROBOT_DESCRIPTION: &str = "/robot_description";

/// The URDF a bag records, with its topic: the last message of
/// `/robot_description`, else of the one `/NS/robot_description`;
/// `None` when the bag records none. An empty message, or several
/// namespaced descriptions and no plain one, is an error.
pub fn robot_description(bag: &Bag) -> Result<Option<(String, String)>, BagError> {
    let named: Vec<&str> = bag
        .topics()
        .iter()
        .filter(|t| {
            t.name == ROBOT_DESCRIPTION
                || (t.name.ends_with(ROBOT_DESCRIPTION)
                    && normalize_type_name(&t.type_name) == "std_msgs/msg/String")
        })
        .map(|t| t.name.as_str())
        .collect();
    let topic = match named[..] {
        [] => return Ok(None),
        [one] => one,
        _ if named.contains(&ROBOT_DESCRIPTION) => ROBOT_DESCRIPTION,
        _ => {
            return Err(topic_error(
                bag,
                ROBOT_DESCRIPTION,
                format!(
                    "not in the bag, and several robots' descriptions are: {}",
                    named.join(", ")
                ),
            ));
        }
    };
    let schema = typed_schema(bag, topic, "std_msgs/msg/String")?;
    let path = schema
        .path_from(0, "data")
        .map_err(|e| topic_error(bag, topic, e))?;
    let mut last = None;
    bag.for_each(topic, |m| {
        let text = m
            .value
            .at(&path)
            .and_then(crate::Value::as_str)
            .ok_or("no string `data`")?;
        last = Some(text.to_string());
        Ok(())
    })?;
    match last {
        Some(text) if !text.trim().is_empty() => Ok(Some((topic.to_string(), text))),
        Some(_) => Err(topic_error(bag, topic, "its message is empty".into())),
        None => Err(topic_error(bag, topic, "no message recorded".into())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Distro;
    use crate::bag::BagWriter;
    use crate::msgs::{Float64, StringMsg};
    use crate::qos::Qos;

    /// A bag (MCAP or sqlite3) with a `std_msgs/msg/String` message per
    /// `(topic, text)`.
    fn bag(dir: &std::path::Path, mcap: bool, messages: &[(&str, &str)]) -> Bag {
        let fill = |w: &mut BagWriter<'_>| {
            let mut ids = Vec::new();
            for (k, (topic, text)) in messages.iter().enumerate() {
                let id = match ids.iter().find(|(t, _)| t == topic) {
                    Some((_, id)) => *id,
                    None => {
                        let id = w.topic::<StringMsg>(topic, Qos::LATCHED).unwrap();
                        ids.push((*topic, id));
                        id
                    }
                };
                let data = text.to_string();
                w.write(id, 1_000 + k as u64, &StringMsg { data }).unwrap();
            }
            let other = w.topic::<Float64>("/speed", Qos::DEFAULT).unwrap();
            w.write(other, 5_000, &Float64 { data: 1.5 }).unwrap();
        };
        let path = if mcap {
            let path = dir.join("d.mcap");
            let f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
            let mut w = BagWriter::mcap(f, "d.mcap", Distro::Jazzy).unwrap();
            fill(&mut w);
            w.finish().unwrap();
            path
        } else {
            let path = dir.join("d.db3");
            let mut w = BagWriter::sqlite3(&path, "d.db3", Distro::Humble).unwrap();
            fill(&mut w);
            w.finish().unwrap();
            path
        };
        Bag::open(&path).unwrap()
    }

    #[test]
    fn the_last_description_is_read_from_either_storage() {
        for mcap in [true, false] {
            let dir = tempfile::tempdir().unwrap();
            let urdf = "<robot name=\"r\">\n<link name=\"base_link\"/>\n</robot>";
            let b = bag(
                dir.path(),
                mcap,
                &[
                    ("/robot_description", "<robot name=\"old\"/>"),
                    ("/robot_description", urdf),
                ],
            );
            assert_eq!(
                robot_description(&b).unwrap(),
                Some(("/robot_description".to_string(), urdf.to_string()))
            );
            // A namespaced robot's, when it is the only one.
            let dir = tempfile::tempdir().unwrap();
            let b = bag(dir.path(), mcap, &[("/rover/robot_description", urdf)]);
            assert_eq!(
                robot_description(&b).unwrap().unwrap().0,
                "/rover/robot_description"
            );
        }
    }

    #[test]
    fn a_bag_without_one_or_with_an_unusable_one_says_so() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(
            robot_description(&bag(dir.path(), true, &[])).unwrap(),
            None
        );
        let cases: [(&[(&str, &str)], &str); 2] = [
            (&[("/robot_description", "  ")], "its message is empty"),
            (
                &[
                    ("/a/robot_description", "<robot/>"),
                    ("/b/robot_description", "<robot/>"),
                ],
                "several robots' descriptions are: /a/robot_description, /b/robot_description",
            ),
        ];
        for (messages, says) in cases {
            let dir = tempfile::tempdir().unwrap();
            let e = robot_description(&bag(dir.path(), false, messages))
                .unwrap_err()
                .to_string();
            assert!(e.contains(says), "{e}");
        }
    }
}
