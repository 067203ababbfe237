//! Refusals in the operator's words. The checks of goals, freedom and
//! redundancy settings name the fields of their files (`waypoints[0].x_m`,
//! `keep_out[1].polygon`), which is right for a file and wrong on the
//! page, where the operator clicked a waypoint or drew a zone: there they
//! read "the x of waypoint 1", "the outline of the keep-out zone
//! 'flowers'".

use twindrive_mission::plan::KeepOutZone;

/// `text` with every field path it names (after "field ", in backquotes,
/// or bare) told as the page names the thing; `zones` are the keep-out
/// zones the command carried (a zone goes by its name).
pub fn in_operator_words(text: &str, zones: &[KeepOutZone]) -> String {
    let text = text.replace(
        "no `[[waypoints]]` and no `[[areas]]`: expected at least one waypoint (the last is the goal) or an area to sweep",
        "no waypoints and no area to sweep: add a waypoint (the last is the goal) or draw an area to sweep",
    );
    let mut out = String::with_capacity(text.len());
    let mut rest = text.as_str();
    while !rest.is_empty() {
        // A path in backquotes, maybe after "field ", or in " (`...`)".
        if let Some(after) = rest
            .strip_prefix("field `")
            .or_else(|| rest.strip_prefix('`'))
            && let Some(end) = after.find('`')
            && let Some(words) = phrase(&after[..end], zones)
        {
            // "area 1 (`areas[0]`)": the words are there already.
            if out.ends_with(" (") && after[end + 1..].starts_with(')') {
                out.truncate(out.len() - 2);
                rest = &after[end + 2..];
                continue;
            }
            out.push_str(&words);
            rest = &after[end + 1..];
            // "… zone 'pit': zone `pit`: …" says the name twice.
            if let Some(zone) = zone_named(&after[..end], zones) {
                let again = format!(": zone `{zone}`");
                if rest.starts_with(&again) {
                    rest = &rest[again.len()..];
                }
            }
            continue;
        }
        // A bare path (a redundancy setting's error).
        let token_len = rest
            .find(|c: char| !(c.is_ascii_alphanumeric() || "_[].".contains(c)))
            .unwrap_or(rest.len());
        let token = rest[..token_len].trim_end_matches('.');
        let word_start = out
            .chars()
            .last()
            .is_none_or(|c| !(c.is_ascii_alphanumeric() || c == '_' || c == '`'));
        if word_start
            && token.contains('_')
            && token.starts_with(|c: char| c.is_ascii_lowercase())
            && let Some(words) = phrase(token, zones)
        {
            out.push_str(&words);
            rest = &rest[token.len()..];
            continue;
        }
        let step = if token_len > 0 {
            token_len
        } else {
            rest.chars().next().map_or(1, char::len_utf8)
        };
        out.push_str(&rest[..step]);
        rest = &rest[step..];
    }
    polygon_words(&out)
}

/// The name of the keep-out zone a `keep_out[i]…` path is about.
fn zone_named<'a>(path: &str, zones: &'a [KeepOutZone]) -> Option<&'a str> {
    let (root, index) = segment(path.split('.').next()?)?;
    (root == "keep_out").then(|| zones.get(index?).map(|z| z.name.as_str()))?
}

/// `name[3]` as ("name", Some(3)); `name` as ("name", None).
fn segment(s: &str) -> Option<(&str, Option<usize>)> {
    match s.split_once('[') {
        Some((name, i)) => Some((name, Some(i.strip_suffix(']')?.parse().ok()?))),
        None => Some((s, None)),
    }
}

/// How the page names the thing at field `path`, if it knows it.
fn phrase(path: &str, zones: &[KeepOutZone]) -> Option<String> {
    let mut parts = path.split('.');
    let (root, index) = segment(parts.next()?)?;
    let field = parts.next();
    if parts.next().is_some() {
        return None;
    }
    let thing = match (root, index) {
        ("waypoints", Some(i)) => format!("waypoint {}", i + 1),
        ("areas", Some(i)) => format!("area {}", i + 1),
        ("keep_out", Some(i)) => match zones.get(i) {
            Some(z) => format!("the keep-out zone '{}'", z.name),
            None => format!("keep-out zone {}", i + 1),
        },
        ("corridor", Some(i)) => format!("corridor region {}", i + 1),
        ("keep_regions", Some(i)) => format!("keep region {}", i + 1),
        ("keep_windows", Some(i)) => format!("keep time window {}", i + 1),
        (setting, None) if field.is_none() => return setting_words(setting).map(str::to_owned),
        _ => return None,
    };
    match field {
        None => Some(thing),
        Some(f) => Some(format!("the {} of {thing}", field_words(f)?)),
    }
}

/// A setting of the goals, the freedom or the redundancy, in words.
fn setting_words(field: &str) -> Option<&'static str> {
    Some(match field {
        "clearance_m" => "the clearance",
        "speed_m_s" => "the speed",
        "max_extra_time_s" => "the time detours may add in all",
        "max_extra_distance_m" => "the distance a detour may add",
        "max_half_width_m" => "the corridor's widest half width",
        "stretch_m" => "the corridor's stretch length",
        "pinch_distance_m" => "the pinch distance",
        "coverage_radius_m" => "the coverage radius",
        "min_loop_length_m" => "the shortest loop cut",
        "min_loop_duration_s" => "the shortest loop's duration",
        _ => return None,
    })
}

/// A field of a waypoint, area, zone, region or window, in words.
fn field_words(field: &str) -> Option<&'static str> {
    Some(match field {
        "x_m" => "x",
        "y_m" => "y",
        "heading_rad" => "heading",
        "dwell_s" => "time to stand",
        "speed_m_s" => "speed",
        "polygon" | "region" => "outline",
        "sweep_radius_m" => "sweep radius",
        "overlap" => "lane overlap",
        "name" => "name",
        "half_width_m" => "half width",
        "radius_m" => "radius",
        "start_s" => "start",
        "end_s" => "end",
        "min_x_m" => "left edge",
        "max_x_m" => "right edge",
        "min_y_m" => "bottom edge",
        "max_y_m" => "top edge",
        _ => return None,
    })
}

/// A polygon check's reasons as about a drawn outline: its corners and
/// sides, counted from 1.
fn polygon_words(text: &str) -> String {
    let mut out = text.replace(
        "a polygon needs at least 3 vertices, got",
        "an outline needs at least 3 corners, got",
    );
    if let Some(at) = out.find("edges ")
        && let Some(end) = out[at..].find(" cross: the polygon must not cross itself")
        && let Some((i, j)) = out[at + 6..at + end].split_once(" and ")
        && let (Ok(i), Ok(j)) = (i.parse::<usize>(), j.parse::<usize>())
    {
        out.replace_range(
            at..at + end + " cross: the polygon must not cross itself".len(),
            &format!(
                "its sides {} and {} cross: draw it without crossing itself",
                i + 1,
                j + 1
            ),
        );
    }
    if let Some(at) = out.find("vertex ")
        && let Some(end) = out[at..].find(" is not finite")
        && let Ok(k) = out[at + 7..at + end].parse::<usize>()
    {
        out.replace_range(
            at..at + end + " is not finite".len(),
            &format!("corner {} is not a number", k + 1),
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn zone(name: &str) -> KeepOutZone {
        KeepOutZone {
            name: name.into(),
            polygon: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]],
        }
    }

    #[test]
    fn field_paths_become_the_things_on_the_page() {
        let zones = [zone("pond"), zone("flowers")];
        for (text, want) in [
            (
                "goals: field `waypoints[0].x_m`: expected a finite number, got NaN",
                "goals: the x of waypoint 1: expected a finite number, got NaN",
            ),
            (
                "goals: field `waypoints[11].speed_m_s`: expected a number > 0, got -1",
                "goals: the speed of waypoint 12: expected a number > 0, got -1",
            ),
            (
                "plan: the robot's freedom, field `keep_out[1].polygon`: zone `flowers`: edges 0 and 2 cross: the polygon must not cross itself",
                "plan: the robot's freedom, the outline of the keep-out zone 'flowers': its sides 1 and 3 cross: draw it without crossing itself",
            ),
            (
                "plan: the robot's freedom, field `corridor[0].half_width_m`: 0.01 m is narrower than the robot's footprint radius 0.15 m",
                "plan: the robot's freedom, the half width of corridor region 1: 0.01 m is narrower than the robot's footprint radius 0.15 m",
            ),
            (
                "goals: area 2 (`areas[1]`): no place inside the area keeps the clearance: nothing to sweep",
                "goals: area 2: no place inside the area keeps the clearance: nothing to sweep",
            ),
            (
                "goals: field `areas[0].polygon`: a polygon needs at least 3 vertices, got 2",
                "goals: the outline of area 1: an outline needs at least 3 corners, got 2",
            ),
            (
                "goals: field `speed_m_s`: 0.9 m/s is above the robot's top speed of 0.40 m/s",
                "goals: the speed: 0.9 m/s is above the robot's top speed of 0.40 m/s",
            ),
            (
                "the pipeline: pinch_distance_m must be > 0, got -1",
                "the pipeline: the pinch distance must be > 0, got -1",
            ),
            (
                "the pipeline: keep_windows[2].end_s must be finite, got NaN",
                "the pipeline: the end of keep time window 3 must be finite, got NaN",
            ),
            (
                "goals: no `[[waypoints]]` and no `[[areas]]`: expected at least one waypoint (the last is the goal) or an area to sweep",
                "goals: no waypoints and no area to sweep: add a waypoint (the last is the goal) or draw an area to sweep",
            ),
            (
                "field `keep_out[5].name`: a zone needs a name",
                "the name of keep-out zone 6: a zone needs a name",
            ),
        ] {
            assert_eq!(in_operator_words(text, &zones), want, "{text}");
        }
    }

    /// What is already in words stays as it was, names and numbers too.
    #[test]
    fn words_stay_words() {
        for text in [
            "goals: waypoint 1 at (4.50, 1.50): the robot's footprint there clears the nearest obstacle by 0.000 m, the route keeps 0.100 m",
            "place: (0.05, 0.05) is inside an obstacle or closer than the footprint to a wall",
            "busy planning; wait for it",
            "upload: plan 0123456789ab is not verified yet; verify it first",
            "no robot `r1`; this console has [\"rover\"]",
            "robot `x_y` is not here",
        ] {
            assert_eq!(in_operator_words(text, &[]), text);
        }
    }
}
