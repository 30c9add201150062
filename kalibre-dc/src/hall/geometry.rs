//! Geometry derived from a hall: server boxes, intake and exhaust faces, distances.

use super::types::{Hall, Rack, Server, Side, Tile};

/// An axis-aligned box `[min, max]` (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Minimum corner.
    pub min: [f64; 3],
    /// Maximum corner.
    pub max: [f64; 3],
}

impl Aabb {
    /// From a minimum corner and a size.
    pub fn from_position_size(position: [f64; 3], size: [f64; 3]) -> Self {
        Aabb {
            min: position,
            max: [
                position[0] + size[0],
                position[1] + size[1],
                position[2] + size[2],
            ],
        }
    }

    /// Centre point.
    pub fn centre(&self) -> [f64; 3] {
        [
            0.5 * (self.min[0] + self.max[0]),
            0.5 * (self.min[1] + self.max[1]),
            0.5 * (self.min[2] + self.max[2]),
        ]
    }

    /// True when the interiors overlap by more than `tol` on every axis.
    pub fn overlaps(&self, other: &Aabb, tol: f64) -> bool {
        (0..3).all(|a| self.min[a] < other.max[a] - tol && other.min[a] < self.max[a] - tol)
    }

    /// True when `other` lies inside `self`, allowing `tol`.
    pub fn contains_box(&self, other: &Aabb, tol: f64) -> bool {
        (0..3).all(|a| other.min[a] >= self.min[a] - tol && other.max[a] <= self.max[a] + tol)
    }

    /// True when the point lies strictly inside, deeper than `tol`.
    pub fn contains_point_strict(&self, p: [f64; 3], tol: f64) -> bool {
        (0..3).all(|a| p[a] > self.min[a] + tol && p[a] < self.max[a] - tol)
    }

    /// True when the point lies inside or on the boundary, allowing `tol`.
    pub fn contains_point(&self, p: [f64; 3], tol: f64) -> bool {
        (0..3).all(|a| p[a] >= self.min[a] - tol && p[a] <= self.max[a] + tol)
    }
}

/// A server with its place in the hall: indices and the box it fills inside its rack.
#[derive(Debug, Clone, Copy)]
pub struct ServerRef<'a> {
    /// Index among all servers of the hall (racks in order, servers in order).
    pub index: usize,
    /// Index of the rack.
    pub rack_index: usize,
    /// The rack.
    pub rack: &'a Rack,
    /// The server.
    pub server: &'a Server,
}

impl Tile {
    /// The column of air above the tile, from the floor up to `height_m`: what a rack,
    /// a CRAC or a floor opening must keep clear of.
    pub fn column(&self, height_m: f64) -> Aabb {
        let [x, y] = self.position_m;
        let [dx, dy] = self.size_m;
        Aabb {
            min: [x, y, 0.0],
            max: [x + dx, y + dy, height_m],
        }
    }
}

impl ServerRef<'_> {
    /// The slab of the rack the server fills: full depth and width, its units' heights.
    pub fn bounds(&self) -> Aabb {
        let r = self.rack;
        let unit_h = r.size_m[2] / r.units.max(1) as f64;
        let z0 = r.position_m[2] + (self.server.u.saturating_sub(1)) as f64 * unit_h;
        let z1 = z0 + self.server.height_u as f64 * unit_h;
        Aabb {
            min: [r.position_m[0], r.position_m[1], z0],
            max: [
                r.position_m[0] + r.size_m[0],
                r.position_m[1] + r.size_m[1],
                z1,
            ],
        }
    }

    /// Centre of the server's intake face.
    pub fn intake_centre(&self) -> [f64; 3] {
        face_centre(&self.bounds(), self.rack.inlet)
    }

    /// Centre of the server's exhaust face.
    pub fn exhaust_centre(&self) -> [f64; 3] {
        face_centre(&self.bounds(), self.rack.inlet.opposite())
    }
}

/// Centre of the face of `b` on `side`.
pub fn face_centre(b: &Aabb, side: Side) -> [f64; 3] {
    let mut c = b.centre();
    let (axis, sign) = side.axis_sign();
    c[axis] = if sign > 0.0 { b.max[axis] } else { b.min[axis] };
    c
}

/// Euclidean distance.
pub fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

impl Hall {
    /// Every server in hall order (racks in order, their servers in order).
    pub fn servers(&self) -> impl Iterator<Item = ServerRef<'_>> + '_ {
        self.racks
            .iter()
            .enumerate()
            .flat_map(|(rack_index, rack)| rack.servers.iter().map(move |s| (rack_index, rack, s)))
            .enumerate()
            .map(|(index, (rack_index, rack, server))| ServerRef {
                index,
                rack_index,
                rack,
                server,
            })
    }

    /// Number of servers.
    pub fn server_count(&self) -> usize {
        self.racks.iter().map(|r| r.servers.len()).sum()
    }

    /// Index of each server's type in `server_types`, in hall order (`None` for an unknown
    /// type, which loading rejects).
    pub fn server_type_indices(&self) -> Vec<Option<usize>> {
        self.servers()
            .map(|s| {
                self.server_types
                    .iter()
                    .position(|t| t.id == s.server.server_type)
            })
            .collect()
    }

    /// The room as a box.
    pub fn room_box(&self) -> Aabb {
        Aabb::from_position_size([0.0; 3], self.room.size_m)
    }
}
