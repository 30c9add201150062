//! The catalogue of server types synthetic halls draw from: a height in rack units and a
//! plausible full-load power range per server entry.

use rand::seq::SliceRandom;
use rand::Rng;

/// One catalogue entry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TypeTemplate {
    /// Type id as written into `hall.json`.
    pub id: &'static str,
    /// Rack units per server entry.
    pub height_u: u32,
    /// Full-load power range of one entry (W).
    pub power_w: (f64, f64),
}

/// Server types seen in production halls (1-4U; a 4U entry may be a multi-node chassis
/// reported as one power reading).
pub(crate) const CATALOGUE: [TypeTemplate; 14] = [
    TypeTemplate {
        id: "1u-web",
        height_u: 1,
        power_w: (180.0, 300.0),
    },
    TypeTemplate {
        id: "1u-compute",
        height_u: 1,
        power_w: (300.0, 450.0),
    },
    TypeTemplate {
        id: "1u-cache",
        height_u: 1,
        power_w: (220.0, 350.0),
    },
    TypeTemplate {
        id: "1u-edge",
        height_u: 1,
        power_w: (150.0, 250.0),
    },
    TypeTemplate {
        id: "2u-db",
        height_u: 2,
        power_w: (450.0, 700.0),
    },
    TypeTemplate {
        id: "2u-storage",
        height_u: 2,
        power_w: (250.0, 400.0),
    },
    TypeTemplate {
        id: "2u-virt",
        height_u: 2,
        power_w: (500.0, 800.0),
    },
    TypeTemplate {
        id: "2u-analytics",
        height_u: 2,
        power_w: (400.0, 650.0),
    },
    TypeTemplate {
        id: "2u-inference",
        height_u: 2,
        power_w: (700.0, 1000.0),
    },
    TypeTemplate {
        id: "3u-hpc",
        height_u: 3,
        power_w: (900.0, 1300.0),
    },
    TypeTemplate {
        id: "4u-gpu",
        height_u: 4,
        power_w: (1200.0, 2000.0),
    },
    TypeTemplate {
        id: "4u-storage",
        height_u: 4,
        power_w: (450.0, 700.0),
    },
    TypeTemplate {
        id: "4u-blade",
        height_u: 4,
        power_w: (1000.0, 1600.0),
    },
    TypeTemplate {
        id: "1u-network",
        height_u: 1,
        power_w: (100.0, 200.0),
    },
];

/// Draws `count` distinct types (in catalogue order), always including a 1U and a 2U
/// type so that racks can reach the preset's server count.
pub(crate) fn draw_types<R: Rng>(rng: &mut R, count: usize) -> Vec<TypeTemplate> {
    let count = count.clamp(2, CATALOGUE.len());
    let mut idx: Vec<usize> = (0..CATALOGUE.len()).collect();
    idx.shuffle(rng);
    let one_u = *idx
        .iter()
        .find(|&&i| CATALOGUE[i].height_u == 1)
        .expect("catalogue has 1U types");
    let two_u = *idx
        .iter()
        .find(|&&i| CATALOGUE[i].height_u == 2)
        .expect("catalogue has 2U types");
    let mut chosen = vec![one_u, two_u];
    for &i in &idx {
        if chosen.len() == count {
            break;
        }
        if !chosen.contains(&i) {
            chosen.push(i);
        }
    }
    chosen.sort_unstable();
    chosen.into_iter().map(|i| CATALOGUE[i]).collect()
}
