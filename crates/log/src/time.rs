//! Simulation time is integer nanoseconds; files carry seconds.

/// Seconds as f64 from integer nanoseconds.
pub fn seconds_from_ns(t_ns: u64) -> f64 {
    t_ns as f64 * 1e-9
}

/// Nearest integer nanoseconds for a time in seconds; `None` if negative or not finite.
pub fn ns_from_seconds(t_s: f64) -> Option<u64> {
    (0.0..1.8e10)
        .contains(&t_s)
        .then(|| (t_s * 1e9).round() as u64)
}

/// Exact decimal seconds ("12.34", "0.000000001", "3").
pub fn format_seconds(t_ns: u64) -> String {
    let mut out = Vec::with_capacity(24);
    push_seconds(&mut out, t_ns);
    String::from_utf8(out).expect("digits and a point are ASCII")
}

/// Appends [`format_seconds`]'s text to `out` without allocating.
pub fn push_seconds(out: &mut Vec<u8>, t_ns: u64) {
    let (sec, nsec) = (t_ns / 1_000_000_000, t_ns % 1_000_000_000);
    out.extend_from_slice(itoa::Buffer::new().format(sec).as_bytes());
    if nsec == 0 {
        return;
    }
    let mut digits = [b'0'; 9];
    let mut rest = nsec;
    for d in digits.iter_mut().rev() {
        *d = b'0' + (rest % 10) as u8;
        rest /= 10;
    }
    let len = 9 - digits.iter().rev().take_while(|&&d| d == b'0').count();
    out.push(b'.');
    out.extend_from_slice(&digits[..len]);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_round_trip_exactly() {
        for t_ns in [
            0,
            1,
            999_999_999,
            1_000_000_000,
            10_000_000,
            3_600_000_000_123,
            86_400_123_456_789,
        ] {
            let text = format_seconds(t_ns);
            let back = ns_from_seconds(text.parse().unwrap()).unwrap();
            assert_eq!(back, t_ns, "{text}");
        }
        assert_eq!(format_seconds(12_340_000_000), "12.34");
        assert_eq!(ns_from_seconds(-1.0), None);
        assert_eq!(ns_from_seconds(f64::NAN), None);
    }
}
