//! Tests of the case geometry: cell ranges, patches and gaps on the block mesh.

use super::*;
use crate::sim::WallSide;
use std::path::Path;

fn dev_hall() -> Hall {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/openfoam/of-dev-clean/hall.json");
    Hall::load(&p).unwrap()
}

#[test]
fn dev_hall_has_the_readme_cell_count_and_patches() {
    let g = CaseGeometry::new(&dev_hall(), 0.2).unwrap();
    // README: 11,140 cells after cutting racks and the CRAC.
    assert_eq!(g.fluid_cells, 11_140);
    assert_eq!(g.servers.len(), 20);
    // A server half of a 0.6 m wide, 1 m high rack face: 3 x 5 faces.
    assert!(g
        .servers
        .iter()
        .all(|s| s.intake.faces == 15 && s.exhaust.faces == 15));
    assert_eq!(g.tiles.iter().map(|t| t.faces).sum::<usize>(), 5 * 12);
    assert_eq!(g.probes.len(), 24);
}

fn openings(boxes: &[Aabb]) -> CaseExtras {
    CaseExtras {
        openings: boxes.to_vec(),
        gaps: vec![],
    }
}

#[test]
fn a_gap_takes_its_band_from_the_servers_and_refuses_to_split_one() {
    let hall = dev_hall();
    let b4 = hall.racks.iter().position(|r| r.id == "B4").unwrap();
    // The blanking dataset's slot: z 1.0-1.2, at the edge of the upper server.
    let slot = RackGap {
        rack: b4,
        z_m: Some([1.0, 1.2]),
    };
    let extras = CaseExtras {
        openings: vec![],
        gaps: vec![slot],
    };
    let g = CaseGeometry::with_extras(&hall, 0.2, &extras).unwrap();
    let gp = &g.gaps[0];
    assert_eq!((gp.rear.faces, gp.front.faces), (3, 3));
    assert_eq!(
        (gp.rear.name.as_str(), gp.front.name.as_str()),
        ("rec0-out", "rec0-in")
    );
    // B4's upper server keeps 3 x 4 faces; every other server its 3 x 5.
    let faces: Vec<usize> = g.servers.iter().map(|s| s.intake.faces).collect();
    assert_eq!(faces.iter().filter(|f| **f == 12).count(), 1);
    assert_eq!(faces.iter().filter(|f| **f == 15).count(), 19);
    // Without a band: the row above the servers' boundary at z 1.0 m, mid-rack.
    let whole = CaseExtras {
        openings: vec![],
        gaps: vec![RackGap {
            rack: b4,
            z_m: None,
        }],
    };
    let g = CaseGeometry::with_extras(&hall, 0.2, &whole).unwrap();
    assert_eq!(g.gaps[0].rear.cells.lo[2], 5);
    assert_eq!(g.gaps[0].rear.cells.hi[2], 6);
    // A band inside a server's span would split it.
    let split = CaseExtras {
        openings: vec![],
        gaps: vec![RackGap {
            rack: b4,
            z_m: Some([0.4, 0.6]),
        }],
    };
    let err = CaseGeometry::with_extras(&hall, 0.2, &split)
        .unwrap_err()
        .to_string();
    assert!(err.contains("splits the server's span"), "{err}");
}

fn floor_box(x: [f64; 2], y: [f64; 2]) -> Aabb {
    Aabb {
        min: [x[0], y[0], 0.0],
        max: [x[1], y[1], 0.0],
    }
}

#[test]
fn a_bypass_opening_becomes_a_floor_patch_of_its_own() {
    // The development bypass dataset's cable cutout: x 3.6-4.2, y 4.2-4.6.
    let cut = floor_box([3.6, 4.2], [4.2, 4.6]);
    let g = CaseGeometry::with_extras(&dev_hall(), 0.2, &openings(&[cut])).unwrap();
    assert_eq!(g.openings.len(), 1);
    let o = &g.openings[0];
    assert_eq!(
        (o.name.as_str(), o.axis, o.plane, o.faces),
        ("byp0", 2, 0, 6)
    );
    assert_eq!(o.cells.lo, [18, 21, 0]);
    assert!(g.patches().any(|p| p.name == "byp0"));
    // The mesh is the same; only faces change patch.
    assert_eq!(g.fluid_cells, 11_140);
}

#[test]
fn openings_on_tiles_off_the_floor_or_off_the_grid_are_refused() {
    let hall = dev_hall();
    let t = &hall.tiles[0];
    let on_tile = floor_box(
        [t.position_m[0], t.position_m[0] + 0.2],
        [t.position_m[1], t.position_m[1] + 0.2],
    );
    let err = CaseGeometry::with_extras(&hall, 0.2, &openings(&[on_tile]))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("overlaps a tile") && err.contains("tile0"),
        "{err}"
    );
    let cut = floor_box([3.6, 4.2], [4.2, 4.6]);
    let err = CaseGeometry::with_extras(&hall, 0.2, &openings(&[cut, cut]))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("bypass opening 1") && err.contains("another opening"),
        "{err}"
    );
    let mut raised = cut;
    raised.max[2] = 0.2;
    let err = CaseGeometry::with_extras(&hall, 0.2, &openings(&[raised]))
        .unwrap_err()
        .to_string();
    assert!(err.contains("not on the floor"), "{err}");
    let off = floor_box([3.65, 4.2], [4.2, 4.6]);
    let err = CaseGeometry::with_extras(&hall, 0.2, &openings(&[off]))
        .unwrap_err()
        .to_string();
    assert!(err.contains("not on the 0.2 m grid"), "{err}");
}

#[test]
fn off_grid_geometry_is_refused_with_the_field() {
    let err = CaseGeometry::new(&dev_hall(), 0.25)
        .unwrap_err()
        .to_string();
    assert!(err.contains("not on the 0.25 m grid"), "{err}");
}

/// The dev hall with one containment box.
fn contained(kind: &str, min_m: [f64; 3], max_m: [f64; 3]) -> Hall {
    let mut h = serde_json::to_value(dev_hall()).unwrap();
    h["containment"] = serde_json::json!([{ "kind": kind, "min_m": min_m, "max_m": max_m }]);
    Hall::from_json_str(&h.to_string(), "contained hall.json").unwrap()
}

#[test]
fn containment_panels_cover_the_fluid_faces_of_each_side_off_the_room_walls() {
    // The cold aisle between the rows, up to the racks' top: two doors and a roof; its
    // long sides are the racks' intakes, so they carry no panel.
    let hall = contained("cold_aisle", [2.4, 1.8, 0.0], [5.4, 3.0, 2.0]);
    let g = CaseGeometry::new(&hall, 0.2).unwrap();
    let got: Vec<(&str, WallSide, usize, usize, usize)> = g
        .panels
        .iter()
        .map(|p| (p.name.as_str(), p.side, p.axis, p.plane, p.faces))
        .collect();
    assert_eq!(
        got,
        [
            ("cont0-xmin", WallSide::MinusX, 0, 12, 6 * 10),
            ("cont0-xmax", WallSide::PlusX, 0, 27, 6 * 10),
            ("cont0-top", WallSide::Top, 2, 10, 15 * 6),
        ]
    );
    // Each porous zone is the cell row on either side of its plane.
    let top = &g.panels[2];
    assert_eq!(top.layer.lo, [12, 9, 9]);
    assert_eq!(top.layer.hi, [27, 15, 11]);
    let xmin = &g.panels[0];
    assert_eq!((xmin.layer.lo[0], xmin.layer.hi[0]), (11, 13));
    // The cut is unchanged: panels take no cells.
    assert_eq!(g.fluid_cells, 11_140);
    // Disjoint porous zones: each plane's own cells, and where a door's layer meets the
    // roof's (one cell row each, 6 cells across the aisle) a zone resisting both normals.
    let zones: Vec<([Option<usize>; 3], usize)> = g
        .panel_zones
        .iter()
        .map(|z| {
            let cells = z.runs.iter().map(|r| r.hi[0] - r.lo[0]).sum();
            (z.axes, cells)
        })
        .collect();
    assert_eq!(
        zones,
        [
            ([None, None, Some(2)], 180 - 2 * 6),
            ([Some(0), None, None], 120 - 6),
            ([Some(0), None, Some(2)], 6),
            ([Some(1), None, None], 120 - 6),
            ([Some(1), None, Some(2)], 6),
        ]
    );

    // A hot aisle against the wall, up to the ceiling: its two doors and the panel
    // above the racks' tops (z 2.0-3.0); no roof, no panel on the wall.
    let hall = contained("hot_aisle", [2.4, 0.0, 0.0], [5.4, 0.8, 3.0]);
    let g = CaseGeometry::new(&hall, 0.2).unwrap();
    let got: Vec<(&str, usize)> = g
        .panels
        .iter()
        .map(|p| (p.name.as_str(), p.faces))
        .collect();
    assert_eq!(
        got,
        [
            ("cont0-xmin", 4 * 15),
            ("cont0-xmax", 4 * 15),
            ("cont0-ymax", 15 * 5)
        ]
    );
}

#[test]
fn containment_off_the_grid_is_refused_with_the_field() {
    let hall = contained("cold_aisle", [2.4, 1.8, 0.0], [5.3, 3.0, 2.0]);
    let err = CaseGeometry::new(&hall, 0.2).unwrap_err().to_string();
    assert!(
        err.contains("/containment/0/max_m/0") && err.contains("not on the 0.2 m grid"),
        "{err}"
    );
}

/// A `front` CRAC's supply enters through the face the built-in simulator blows
/// through, over its whole height; with no grilles every CRAC draws its air in at its
/// top, and a hall of floor CRACs and grilles has neither.
#[test]
fn a_front_crac_blows_through_its_face_and_without_grilles_cracs_draw_at_their_tops() {
    let floor = CaseGeometry::new(&dev_hall(), 0.2).unwrap();
    assert!(floor.crac_supplies.is_empty() && floor.crac_returns.is_empty());
    let mut hall = dev_hall();
    hall.cracs[0].supply = SupplyKind::Front;
    hall.tiles.clear();
    let g = CaseGeometry::new(&hall, 0.2).unwrap();
    // The CRAC stands against the x = 0 wall, 0.8 m deep, 1.6 m wide, 2 m high: its
    // +x face at x 0.8 m, 8 x 10 faces.
    let sup = &g.crac_supplies[0];
    assert_eq!(
        (
            sup.crac,
            sup.patch.name.as_str(),
            sup.patch.axis,
            sup.patch.plane
        ),
        (0, "sup0", 0, 4)
    );
    assert_eq!(sup.patch.faces, 80);
    assert!(g.crac_returns.is_empty(), "the grilles return the air");
    hall.returns.clear();
    let g = CaseGeometry::new(&hall, 0.2).unwrap();
    let top = &g.crac_returns[0];
    assert_eq!(
        (
            top.patch.name.as_str(),
            top.patch.axis,
            top.patch.plane,
            top.patch.faces
        ),
        ("crt0", 2, 10, 4 * 8)
    );
    let names: Vec<&str> = g.patches().map(|p| p.name.as_str()).collect();
    assert!(
        names.contains(&"sup0") && names.contains(&"crt0"),
        "{names:?}"
    );
    // A CRAC up to the ceiling has no top to draw through.
    hall.cracs[0].size_m[2] = 3.0;
    let e = CaseGeometry::new(&hall, 0.2).unwrap_err().to_string();
    assert!(
        e.contains("/cracs/0") && e.contains("reaches the ceiling"),
        "{e}"
    );
}
