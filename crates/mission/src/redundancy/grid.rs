//! A uniform grid hash: square cells, a hand-written open-addressing table
//! from cell coordinates to dense cell ids, and each cell's entries in one
//! flat array in the order they were added (a counting sort).

use super::geometry::Point;

/// "No cell" in neighbour lists and table slots.
pub(super) const NO_CELL: u32 = u32::MAX;

/// Something to index at a point, with the index (`tag`) it stands for.
#[derive(Debug, Clone, Copy)]
pub(super) struct Anchor {
    pub pos: Point,
    pub tag: u32,
    /// A sample's own position, rather than a point along a segment.
    /// Consecutive samples at one position become one entry (a robot
    /// standing still is one entry, not many).
    pub is_sample: bool,
}

/// Tags `first..=last`, all anchored at `pos`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Entry {
    pub first: u32,
    pub last: u32,
    /// The samples' position; NaN for an anchor along a segment, so that
    /// distance tests on it fail.
    pub pos: Point,
}

/// The grid: entries of cell `c` are `entries[starts[c]..starts[c + 1]]`,
/// sorted by tag when anchors were added in tag order.
pub(super) struct Grid {
    starts: Vec<u32>,
    entries: Vec<Entry>,
    neighbours: Vec<[u32; 9]>,
    /// The largest tag in the 3×3 cells around each cell.
    latest_around: Vec<u32>,
}

impl Grid {
    /// Indexes the anchors in cells of `cell_m`; also returns each anchor's
    /// cell id, in order.
    pub fn build(
        cell_m: f64,
        capacity: usize,
        anchors: impl Iterator<Item = Anchor>,
    ) -> (Self, Vec<u32>) {
        let mut ids = CellIds::default();
        let mut coords: Vec<(i32, i32)> = Vec::new();
        let mut anchor_cell = Vec::with_capacity(capacity);
        let mut raw: Vec<(u32, Entry)> = Vec::with_capacity(capacity);
        let mut last_is_sample = false;
        let mut last_cell = None;
        for a in anchors {
            let cell = cell_of(a.pos, cell_m);
            // Paths move little from one anchor to the next.
            let id = match last_cell {
                Some((c, id)) if c == cell => id,
                _ => {
                    let id = ids.id_or_insert(cell, || {
                        coords.push(cell);
                        (coords.len() - 1) as u32
                    });
                    last_cell = Some((cell, id));
                    id
                }
            };
            anchor_cell.push(id);
            if let Some((_, e)) = raw.last_mut()
                && a.is_sample
                && last_is_sample
                && e.pos == a.pos
                && e.last + 1 == a.tag
            {
                e.last = a.tag;
                continue;
            }
            raw.push((
                id,
                Entry {
                    first: a.tag,
                    last: a.tag,
                    pos: if a.is_sample { a.pos } else { [f64::NAN; 2] },
                },
            ));
            last_is_sample = a.is_sample;
        }

        let (starts, entries) = by_cell(coords.len(), raw);
        let neighbours = ids.neighbours(&coords);
        let latest: Vec<u32> = (0..coords.len())
            .map(|c| entries[starts[c + 1] as usize - 1].last)
            .collect();
        let latest_around = neighbours
            .iter()
            .map(|around| {
                around
                    .iter()
                    .filter(|&&c| c != NO_CELL)
                    .map(|&c| latest[c as usize])
                    .max()
                    .unwrap_or(0)
            })
            .collect();
        (
            Self {
                starts,
                entries,
                neighbours,
                latest_around,
            },
            anchor_cell,
        )
    }

    /// The largest tag in the cell and its neighbours: a query for tags
    /// above it can stop before it starts.
    #[inline]
    pub fn latest_around(&self, cell: u32) -> u32 {
        self.latest_around[cell as usize]
    }

    /// The cell itself and its eight neighbours that hold entries
    /// (`NO_CELL` for the others).
    #[inline]
    pub fn neighbours(&self, cell: u32) -> &[u32; 9] {
        &self.neighbours[cell as usize]
    }

    #[inline]
    pub fn entries(&self, cell: u32) -> &[Entry] {
        let c = cell as usize;
        &self.entries[self.starts[c] as usize..self.starts[c + 1] as usize]
    }
}

/// Items tagged with a cell id, grouped by cell (a counting sort, so each
/// cell keeps its items in the order given): cell `c`'s items are
/// `items[starts[c]..starts[c + 1]]`.
pub(super) fn by_cell<T: Copy>(cells: usize, tagged: Vec<(u32, T)>) -> (Vec<u32>, Vec<T>) {
    let mut starts = vec![0u32; cells + 1];
    for &(id, _) in &tagged {
        starts[id as usize + 1] += 1;
    }
    for c in 0..cells {
        starts[c + 1] += starts[c];
    }
    let Some(&(_, any)) = tagged.first() else {
        return (starts, Vec::new());
    };
    let mut fill = starts.clone();
    // Every slot is written: the counts add up to the items.
    let mut items = vec![any; tagged.len()];
    for (id, item) in tagged {
        items[fill[id as usize] as usize] = item;
        fill[id as usize] += 1;
    }
    (starts, items)
}

/// Integer cell coordinates. Callers choose `cell_m` so that they stay
/// well inside `i32` (the cast saturates anyway).
#[inline]
pub(super) fn cell_of(p: Point, cell_m: f64) -> (i32, i32) {
    (
        (p[0] / cell_m).floor() as i32,
        (p[1] / cell_m).floor() as i32,
    )
}

/// Cell coordinates -> dense cell id. Cells are grouped in tiles of
/// `TILE × TILE`; a hash table finds a tile, an array inside it the cell.
/// A path stays in one tile for many cells, so most look-ups, and most
/// neighbour look-ups, never touch the hash table.
#[derive(Default)]
pub(super) struct CellIds {
    tiles: CellTable,
    cells: Vec<[u32; TILE * TILE]>,
    last_tile: Option<((i32, i32), u32)>,
}

const TILE_BITS: u32 = 3;
const TILE: usize = 1 << TILE_BITS;

#[inline]
fn split((cx, cy): (i32, i32)) -> ((i32, i32), usize) {
    let mask = TILE as i32 - 1;
    (
        (cx >> TILE_BITS, cy >> TILE_BITS),
        ((cx & mask) | ((cy & mask) << TILE_BITS)) as usize,
    )
}

impl CellIds {
    pub fn id(&self, cell: (i32, i32)) -> u32 {
        let (tile, slot) = split(cell);
        match self.tiles.id(tile) {
            NO_CELL => NO_CELL,
            t => self.cells[t as usize][slot],
        }
    }

    pub fn id_or_insert(&mut self, cell: (i32, i32), new_id: impl FnOnce() -> u32) -> u32 {
        let (tile, slot) = split(cell);
        let t = match self.last_tile {
            Some((k, t)) if k == tile => t,
            _ => {
                let cells = &mut self.cells;
                let t = self.tiles.id_or_insert(tile, || {
                    cells.push([NO_CELL; TILE * TILE]);
                    (cells.len() - 1) as u32
                });
                self.last_tile = Some((tile, t));
                t
            }
        };
        let id = &mut self.cells[t as usize][slot];
        if *id == NO_CELL {
            *id = new_id();
        }
        *id
    }

    /// The 3×3 neighbourhood of every cell, `coords` in id order.
    pub fn neighbours(&self, coords: &[(i32, i32)]) -> Vec<[u32; 9]> {
        // Tile ids around the tile of the previous cell: consecutive cells
        // are mostly in one tile.
        let mut around_tile: Option<((i32, i32), [u32; 9])> = None;
        coords
            .iter()
            .map(|&(cx, cy)| {
                let (tile, _) = split((cx, cy));
                let tiles = match around_tile {
                    Some((k, ids)) if k == tile => ids,
                    _ => {
                        let mut ids = [NO_CELL; 9];
                        for (k, id) in ids.iter_mut().enumerate() {
                            let (dx, dy) = (k as i32 % 3 - 1, k as i32 / 3 - 1);
                            *id = self.tiles.id((tile.0 + dx, tile.1 + dy));
                        }
                        around_tile = Some((tile, ids));
                        ids
                    }
                };
                let mut around = [NO_CELL; 9];
                for (k, id) in around.iter_mut().enumerate() {
                    let (dx, dy) = (k as i32 % 3 - 1, k as i32 / 3 - 1);
                    let (t, slot) = split((cx + dx, cy + dy));
                    let which = (t.0 - tile.0 + 1) + 3 * (t.1 - tile.1 + 1);
                    let tile_id = tiles[which as usize];
                    if tile_id != NO_CELL {
                        *id = self.cells[tile_id as usize][slot];
                    }
                }
                around
            })
            .collect()
    }
}

/// Tile coordinates -> dense id; linear probing, Fibonacci hashing.
struct CellTable {
    keys: Vec<u64>,
    ids: Vec<u32>,
    shift: u32,
    len: usize,
}

impl Default for CellTable {
    fn default() -> Self {
        Self::with_capacity(64)
    }
}

impl CellTable {
    fn with_capacity(cells: usize) -> Self {
        let slots = (cells.max(8) * 2).next_power_of_two();
        Self {
            keys: vec![0; slots],
            ids: vec![NO_CELL; slots],
            shift: 64 - slots.trailing_zeros(),
            len: 0,
        }
    }

    #[inline]
    fn key((cx, cy): (i32, i32)) -> u64 {
        (u64::from(cx as u32) << 32) | u64::from(cy as u32)
    }

    #[inline]
    fn slot(&self, key: u64) -> usize {
        (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> self.shift) as usize
    }

    fn id(&self, cell: (i32, i32)) -> u32 {
        let key = Self::key(cell);
        let mask = self.keys.len() - 1;
        let mut s = self.slot(key);
        loop {
            if self.ids[s] == NO_CELL || self.keys[s] == key {
                return self.ids[s];
            }
            s = (s + 1) & mask;
        }
    }

    fn id_or_insert(&mut self, cell: (i32, i32), new_id: impl FnOnce() -> u32) -> u32 {
        if 2 * (self.len + 1) > self.keys.len() {
            self.grow();
        }
        let key = Self::key(cell);
        let mask = self.keys.len() - 1;
        let mut s = self.slot(key);
        loop {
            if self.ids[s] == NO_CELL {
                let id = new_id();
                self.keys[s] = key;
                self.ids[s] = id;
                self.len += 1;
                return id;
            }
            if self.keys[s] == key {
                return self.ids[s];
            }
            s = (s + 1) & mask;
        }
    }

    fn grow(&mut self) {
        let mut bigger = Self::with_capacity(self.keys.len());
        for (&key, &id) in self.keys.iter().zip(&self.ids) {
            if id != NO_CELL {
                let mask = bigger.keys.len() - 1;
                let mut s = bigger.slot(key);
                while bigger.ids[s] != NO_CELL {
                    s = (s + 1) & mask;
                }
                bigger.keys[s] = key;
                bigger.ids[s] = id;
            }
        }
        bigger.len = self.len;
        *self = bigger;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_by_cell_in_tag_order_with_runs_merged() {
        let pts = [
            [0.5, 0.5],
            [0.5, 0.5],
            [0.5, 0.5],
            [1.5, 0.5],
            [0.6, 0.5],
            [-0.5, -3.5],
        ];
        let anchors = pts.iter().enumerate().map(|(k, &pos)| Anchor {
            pos,
            tag: k as u32,
            is_sample: true,
        });
        let (grid, cells) = Grid::build(1.0, pts.len(), anchors);
        assert_eq!(cells, vec![0, 0, 0, 1, 0, 2]);
        let tags = |c: u32| -> Vec<(u32, u32)> {
            grid.entries(c).iter().map(|e| (e.first, e.last)).collect()
        };
        assert_eq!(tags(0), vec![(0, 2), (4, 4)]);
        assert_eq!(tags(1), vec![(3, 3)]);
        assert_eq!(tags(2), vec![(5, 5)]);
        assert_eq!(grid.neighbours(0)[4], 0);
        assert_eq!(grid.neighbours(0)[5], 1);
        assert_eq!(grid.latest_around(0), 4);
        assert_eq!(grid.latest_around(2), 5);
        assert_eq!(
            grid.neighbours(2).iter().filter(|&&c| c != NO_CELL).count(),
            1
        );
    }

    #[test]
    fn table_grows_and_finds_everything() {
        let mut t = CellTable::with_capacity(1);
        for k in 0..10_000i32 {
            let id = t.id_or_insert((k % 137 - 60, k / 137 - 30), || k as u32);
            assert_eq!(id, k as u32);
        }
        for k in 0..10_000i32 {
            assert_eq!(t.id((k % 137 - 60, k / 137 - 30)), k as u32);
        }
        assert_eq!(t.id((1000, 1000)), NO_CELL);
    }
}
