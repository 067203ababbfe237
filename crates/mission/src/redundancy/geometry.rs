//! The two predicates every finder shares, written once so that the fast
//! and the reference finders (and the Python peer, which spells out the same
//! floating-point operations) agree to the bit.

pub(super) type Point = [f64; 2];

/// Squared distance; pinches compare it with the squared pinch distance.
#[inline]
pub(super) fn distance2(a: Point, b: Point) -> f64 {
    let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
    dx * dx + dy * dy
}

/// Euclidean distance (`sqrt` is correctly rounded; `hypot` is not the
/// same everywhere).
#[inline]
pub(super) fn distance(a: Point, b: Point) -> f64 {
    distance2(a, b).sqrt()
}

/// Squared distance from `s` to the closed segment `p q` (to the point `p`
/// when `p == q`): the coverage predicate every finder shares.
#[inline]
pub(super) fn segment_distance2(s: Point, p: Point, q: Point) -> f64 {
    let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
    let (ex, ey) = (s[0] - p[0], s[1] - p[1]);
    let dot = ex * dx + ey * dy;
    if dot <= 0.0 {
        return ex * ex + ey * ey;
    }
    let length2 = dx * dx + dy * dy;
    if dot >= length2 {
        return distance2(s, q);
    }
    let t = dot / length2;
    let (fx, fy) = (ex - t * dx, ey - t * dy);
    fx * fx + fy * fy
}

/// Squared distance from `s` to the box `lo..=hi` (zero inside).
#[inline]
pub(super) fn box_distance2(s: Point, lo: Point, hi: Point) -> f64 {
    let dx = (lo[0] - s[0]).max(s[0] - hi[0]).max(0.0);
    let dy = (lo[1] - s[1]).max(s[1] - hi[1]).max(0.0);
    dx * dx + dy * dy
}

/// Twice the signed area of the triangle `a b c` (> 0: counter-clockwise).
#[inline]
fn orient(a: Point, b: Point, c: Point) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Whether `p` lies in the bounding box of `a b`.
#[inline]
fn in_box(a: Point, b: Point, p: Point) -> bool {
    a[0].min(b[0]) <= p[0]
        && p[0] <= a[0].max(b[0])
        && a[1].min(b[1]) <= p[1]
        && p[1] <= a[1].max(b[1])
}

/// Whether the closed segments `p1 p2` and `p3 p4` share a point: a proper
/// crossing, or an end touching the other segment, or a collinear overlap.
/// Segments whose bounding boxes are apart never meet, however the
/// orientations round, so only segments that (nearly) touch can answer yes.
#[inline]
pub(super) fn segments_meet(p1: Point, p2: Point, p3: Point, p4: Point) -> bool {
    if p1[0].max(p2[0]) < p3[0].min(p4[0])
        || p3[0].max(p4[0]) < p1[0].min(p2[0])
        || p1[1].max(p2[1]) < p3[1].min(p4[1])
        || p3[1].max(p4[1]) < p1[1].min(p2[1])
    {
        return false;
    }
    let d1 = orient(p3, p4, p1);
    let d2 = orient(p3, p4, p2);
    let d3 = orient(p1, p2, p3);
    let d4 = orient(p1, p2, p4);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && in_box(p3, p4, p1))
        || (d2 == 0.0 && in_box(p3, p4, p2))
        || (d3 == 0.0 && in_box(p1, p2, p3))
        || (d4 == 0.0 && in_box(p1, p2, p4))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_to_a_segment_its_ends_and_a_point() {
        let (p, q) = ([0.0, 0.0], [2.0, 0.0]);
        assert_eq!(segment_distance2([1.0, 3.0], p, q), 9.0);
        assert_eq!(segment_distance2([-3.0, 4.0], p, q), 25.0);
        assert_eq!(segment_distance2([5.0, 4.0], p, q), 25.0);
        assert_eq!(segment_distance2([1.0, 0.0], p, q), 0.0);
        assert_eq!(segment_distance2([3.0, 4.0], p, p), 25.0);
        assert_eq!(box_distance2([1.0, 1.0], [0.0, 0.0], [2.0, 2.0]), 0.0);
        assert_eq!(box_distance2([5.0, 6.0], [0.0, 0.0], [2.0, 2.0]), 25.0);
    }

    #[test]
    fn crossing_touching_and_apart() {
        assert!(segments_meet(
            [0.0, 0.0],
            [2.0, 2.0],
            [0.0, 2.0],
            [2.0, 0.0]
        ));
        // An end on the other segment.
        assert!(segments_meet(
            [0.0, 0.0],
            [2.0, 0.0],
            [1.0, 0.0],
            [1.0, 5.0]
        ));
        // Collinear overlap, and collinear apart.
        assert!(segments_meet(
            [0.0, 0.0],
            [2.0, 0.0],
            [1.0, 0.0],
            [3.0, 0.0]
        ));
        assert!(!segments_meet(
            [0.0, 0.0],
            [1.0, 0.0],
            [2.0, 0.0],
            [3.0, 0.0]
        ));
        // Parallel, and crossing lines but not segments.
        assert!(!segments_meet(
            [0.0, 0.0],
            [2.0, 0.0],
            [0.0, 1.0],
            [2.0, 1.0]
        ));
        assert!(!segments_meet(
            [0.0, 0.0],
            [1.0, 1.0],
            [3.0, 0.0],
            [2.0, 1.0]
        ));
        // A point on a segment.
        assert!(segments_meet(
            [1.0, 1.0],
            [1.0, 1.0],
            [0.0, 0.0],
            [2.0, 2.0]
        ));
    }
}
