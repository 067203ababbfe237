//! The exact Euclidean distance transform of a grid (Felzenszwalb and
//! Huttenlocher): the distance of every cell to the nearest obstacle cell,
//! in linear time. The twin's site grid ([`crate::site_grid`]) and the
//! robot's local planner (`twindrive_agent::local_planner`) both use it.

/// Buffers [`edt`] reuses from one call to the next.
#[derive(Debug, Default)]
pub struct Scratch {
    f: Vec<f64>,
    d: Vec<f64>,
    v: Vec<usize>,
    z: Vec<f64>,
}

/// The exact squared Euclidean distance transform of `f` (0 on obstacles,
/// a large number elsewhere), in cells², in place: one dimension at a
/// time, each the lower envelope of parabolas (Felzenszwalb and
/// Huttenlocher, "Distance Transforms of Sampled Functions", 2012).
pub fn edt(f: &mut [f64], size: [usize; 2], s: &mut Scratch) {
    let [w, h] = size;
    let n = w.max(h);
    s.f.resize(n, 0.0);
    s.d.resize(n, 0.0);
    s.v.resize(n, 0);
    s.z.resize(n + 1, 0.0);
    for j in 0..h {
        for i in 0..w {
            s.f[i] = f[i + j * w];
        }
        edt_1d(w, s);
        for i in 0..w {
            f[i + j * w] = s.d[i];
        }
    }
    for i in 0..w {
        for j in 0..h {
            s.f[j] = f[i + j * w];
        }
        edt_1d(h, s);
        for j in 0..h {
            f[i + j * w] = s.d[j];
        }
    }
}

fn edt_1d(n: usize, s: &mut Scratch) {
    let (f, d, v, z) = (&s.f, &mut s.d, &mut s.v, &mut s.z);
    let mut k = 0usize;
    v[0] = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    let meet = |q: usize, p: usize| {
        let (qf, pf) = (q as f64, p as f64);
        ((f[q] + qf * qf) - (f[p] + pf * pf)) / (2.0 * (qf - pf))
    };
    for q in 1..n {
        let mut x = meet(q, v[k]);
        while x <= z[k] {
            k -= 1;
            x = meet(q, v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = x;
        z[k + 1] = f64::INFINITY;
    }
    k = 0;
    for (q, dq) in d.iter_mut().enumerate().take(n) {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let dx = q as f64 - v[k] as f64;
        *dq = dx * dx + f[v[k]];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn the_distance_transform_is_exact_on_random_obstacles() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..5 {
            let size = [rng.random_range(5..40), rng.random_range(5..40)];
            let n = size[0] * size[1];
            let obstacles: Vec<usize> = (0..rng.random_range(1..8))
                .map(|_| rng.random_range(0..n))
                .collect();
            let mut f: Vec<f64> = (0..n)
                .map(|c| if obstacles.contains(&c) { 0.0 } else { 1e12 })
                .collect();
            edt(&mut f, size, &mut Scratch::default());
            for (c, got) in f.iter().enumerate() {
                let (i, j) = ((c % size[0]) as f64, (c / size[0]) as f64);
                let want = obstacles
                    .iter()
                    .map(|&o| {
                        let (oi, oj) = ((o % size[0]) as f64, (o / size[0]) as f64);
                        (i - oi).powi(2) + (j - oj).powi(2)
                    })
                    .fold(f64::INFINITY, f64::min);
                assert_eq!(*got, want, "cell {c} of {size:?}");
            }
        }
    }
}
