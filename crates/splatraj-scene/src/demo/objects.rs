//! The room's parts, each described once: its label name and the function that adds its
//! surfaces (shape, density weight, material, colour). The published boxes of
//! [`super::demo_layout`] are derived from these surfaces, and the label ids are the order of
//! [`OBJECTS`]. Object builders run in that order and draw their colour tints from the
//! scene's generator in that order, so the scene of a seed never changes.

use std::f64::consts::{PI, TAU};

use glam::DVec3;
use rand_chacha::ChaCha8Rng;

use super::DEMO_TABLE_TOP_Z;
use super::looks::{
    GLOSSY, Light, Look, MATTE, Opacity, Paint, ROOM, floor_color, hash01, plain, table_color,
    tinted, wall_color,
};
use super::shapes::{Shape, box_faces, flat_ring, upright};

/// One labelled part of the room: its label name and what it is made of.
pub(super) struct ObjectSpec {
    /// Label name.
    pub(super) name: &'static str,
    /// Adds its surfaces to the parts (drawing its colour tints from the generator).
    build: fn(&mut Parts, &mut ChaCha8Rng),
}

const fn spec(name: &'static str, build: fn(&mut Parts, &mut ChaCha8Rng)) -> ObjectSpec {
    ObjectSpec { name, build }
}

/// Every labelled part, by label id: floor, walls and table, then the objects.
pub(super) const OBJECTS: [ObjectSpec; 11] = [
    spec("floor", floor),
    spec("walls", walls),
    spec("table", table),
    spec("red mug", red_mug),
    spec("green ball", green_ball),
    spec("blue box", blue_box),
    spec("yellow cone", yellow_cone),
    spec("lamp", lamp),
    spec("books", books),
    spec("plant", plant),
    spec("glass of water", glass_of_water),
];

/// A surface with its label, colour and material.
pub(super) struct Part {
    pub(super) label: i32,
    pub(super) shape: Shape,
    /// Density multiplier within the label (hidden undersides get fewer).
    pub(super) weight: f64,
    pub(super) area: f64,
    pub(super) look: Look,
    pub(super) paint: Paint,
}

/// Collects parts, computing their areas; `add` labels them with the object being built.
pub(super) struct Parts {
    parts: Vec<Part>,
    label: i32,
}

impl Parts {
    fn add(&mut self, shape: Shape, weight: f64, look: Look, paint: Paint) {
        let area = shape.area();
        self.parts.push(Part {
            label: self.label,
            shape,
            weight,
            area,
            look,
            paint,
        });
    }
}

/// The surfaces of every object, in label order; the generator gives the colour tints.
pub(super) fn build_parts(rng: &mut ChaCha8Rng) -> Vec<Part> {
    let mut parts = Parts {
        parts: Vec::new(),
        label: 0,
    };
    for (label, object) in (0..).zip(&OBJECTS) {
        parts.label = label;
        (object.build)(&mut parts, rng);
    }
    parts.parts
}

/// The floor, 4 × 4 m.
fn floor(parts: &mut Parts, _rng: &mut ChaCha8Rng) {
    let x = DVec3::X;
    let y = DVec3::Y;
    parts.add(
        Shape::Rect {
            origin: DVec3::new(-2.0, -2.0, 0.0),
            a: 4.0 * x,
            b: 4.0 * y,
        },
        1.0,
        ROOM,
        Box::new(|p, _, _| floor_color(p)),
    );
}

/// Two walls (the room is open towards +x and −y so cameras can stand back).
fn walls(parts: &mut Parts, _rng: &mut ChaCha8Rng) {
    let x = DVec3::X;
    let y = DVec3::Y;
    let z = DVec3::Z;
    parts.add(
        Shape::Rect {
            origin: DVec3::new(-2.0, 2.0, 0.0),
            a: 4.0 * x,
            b: 2.5 * z,
        },
        1.0,
        ROOM,
        Box::new(|p, _, _| wall_color(p)),
    );
    parts.add(
        Shape::Rect {
            origin: DVec3::new(-2.0, -2.0, 0.0),
            a: 4.0 * y,
            b: 2.5 * z,
        },
        1.0,
        ROOM,
        Box::new(|p, _, _| wall_color(p)),
    );
}

/// A 4 cm top slab and four 5 cm square legs.
fn table(parts: &mut Parts, _rng: &mut ChaCha8Rng) {
    let top = f64::from(DEMO_TABLE_TOP_Z);
    let slab = box_faces(DVec3::new(0.0, 0.0, top - 0.04), 0.8, 0.5, 0.04, 0.0);
    for (k, face) in slab.into_iter().enumerate() {
        let weight = if k == 1 { 0.25 } else { 1.0 };
        parts.add(face, weight, MATTE, Box::new(|p, _, _| table_color(p)));
    }
    for (lx, ly) in [(0.7, 0.4), (-0.7, 0.4), (0.7, -0.4), (-0.7, -0.4)] {
        let leg = box_faces(DVec3::new(lx, ly, 0.0), 0.025, 0.025, top - 0.04, 0.0);
        for face in leg.into_iter().skip(2) {
            parts.add(
                face,
                1.0,
                MATTE,
                Box::new(|_, _, v| DVec3::new(0.40, 0.26, 0.16) * (0.9 + 0.1 * v)),
            );
        }
    }
}

/// Red mug, 9 cm wide and 10 cm tall, white inside, handle towards +x.
fn red_mug(parts: &mut Parts, rng: &mut ChaCha8Rng) {
    let x = DVec3::X;
    let z = DVec3::Z;
    let top = f64::from(DEMO_TABLE_TOP_Z);
    let c = DVec3::new(0.30, -0.22, top);
    let red = tinted(rng, DVec3::new(0.80, 0.10, 0.09));
    let cream = tinted(rng, DVec3::new(0.93, 0.90, 0.84));
    parts.add(
        upright(c, 0.045, 0.045, 0.10, false),
        1.0,
        GLOSSY,
        plain(red),
    );
    parts.add(
        upright(c + 0.006 * z, 0.041, 0.041, 0.094, true),
        1.0,
        MATTE,
        plain(cream),
    );
    parts.add(
        flat_ring(c + 0.10 * z, 0.041, 0.045, false),
        1.0,
        GLOSSY,
        plain(red),
    );
    parts.add(
        flat_ring(c + 0.006 * z, 0.0, 0.041, false),
        1.0,
        MATTE,
        plain(cream),
    );
    parts.add(flat_ring(c, 0.0, 0.045, true), 0.3, MATTE, plain(red));
    parts.add(
        Shape::Torus {
            center: c + 0.045 * x + 0.05 * z,
            e1: x,
            e2: z,
            major: 0.03,
            minor: 0.008,
            a0: -0.45 * PI,
            a1: 0.45 * PI,
        },
        1.5,
        GLOSSY,
        plain(red),
    );
}

/// Green ball, 14 cm across.
fn green_ball(parts: &mut Parts, rng: &mut ChaCha8Rng) {
    let top = f64::from(DEMO_TABLE_TOP_Z);
    let green = tinted(rng, DVec3::new(0.16, 0.66, 0.22));
    parts.add(
        Shape::Sphere {
            center: DVec3::new(-0.40, -0.15, top + 0.07),
            radius: 0.07,
        },
        1.0,
        GLOSSY,
        Box::new(move |p, _, _| {
            // A pale seam around the ball makes its spin readable.
            let seam = (p.z - (top + 0.07) + 0.02 * (p.x * 60.0).sin()).abs() < 0.004;
            if seam { DVec3::splat(0.9) } else { green }
        }),
    );
}

/// Blue box, 16 × 7 × 22 cm, a white label band on its front (−y) face.
fn blue_box(parts: &mut Parts, rng: &mut ChaCha8Rng) {
    let top = f64::from(DEMO_TABLE_TOP_Z);
    let blue = tinted(rng, DVec3::new(0.10, 0.24, 0.78));
    let faces = box_faces(DVec3::new(-0.05, 0.0, top), 0.08, 0.035, 0.22, 0.0);
    for (k, face) in faces.into_iter().enumerate() {
        let weight = if k == 1 { 0.2 } else { 1.0 };
        let paint: Paint = if k == 5 {
            Box::new(move |p, _, _| {
                let band = (top + 0.09..top + 0.15).contains(&p.z);
                let stripe = (top + 0.11..top + 0.125).contains(&p.z) && p.x < -0.01;
                match (band, stripe) {
                    (true, true) => DVec3::new(0.85, 0.15, 0.12),
                    (true, false) => DVec3::splat(0.94),
                    _ => blue,
                }
            })
        } else {
            plain(blue)
        };
        parts.add(face, weight, MATTE, paint);
    }
}

/// Yellow cone, 12 cm base, 16 cm tall.
fn yellow_cone(parts: &mut Parts, rng: &mut ChaCha8Rng) {
    let top = f64::from(DEMO_TABLE_TOP_Z);
    let yellow = tinted(rng, DVec3::new(0.96, 0.80, 0.10));
    let c = DVec3::new(0.55, 0.25, top);
    parts.add(
        upright(c, 0.06, 0.0, 0.16, false),
        1.0,
        MATTE,
        plain(yellow),
    );
    parts.add(flat_ring(c, 0.0, 0.06, true), 0.3, MATTE, plain(yellow));
}

/// Lamp, 40 cm tall: round base, thin pole, bulb inside an open conical shade.
fn lamp(parts: &mut Parts, rng: &mut ChaCha8Rng) {
    let z = DVec3::Z;
    let top = f64::from(DEMO_TABLE_TOP_Z);
    let c = DVec3::new(-0.55, 0.28, top);
    let bronze = tinted(rng, DVec3::new(0.30, 0.25, 0.20));
    let shade = tinted(rng, DVec3::new(0.93, 0.86, 0.70));
    let glow = DVec3::new(1.0, 0.96, 0.82);
    parts.add(
        upright(c, 0.08, 0.08, 0.02, false),
        1.0,
        GLOSSY,
        plain(bronze),
    );
    parts.add(
        flat_ring(c + 0.02 * z, 0.0, 0.08, false),
        1.0,
        GLOSSY,
        plain(bronze),
    );
    parts.add(
        upright(c + 0.02 * z, 0.008, 0.008, 0.28, false),
        2.0,
        GLOSSY,
        plain(DVec3::new(0.72, 0.72, 0.74)),
    );
    parts.add(
        upright(c + 0.26 * z, 0.12, 0.065, 0.14, false),
        1.0,
        MATTE,
        plain(shade),
    );
    let emissive = Look {
        light: Light::Emissive,
        ..MATTE
    };
    parts.add(
        upright(c + 0.26 * z, 0.117, 0.062, 0.14, true),
        0.7,
        emissive,
        plain(glow),
    );
    parts.add(
        Shape::Sphere {
            center: c + 0.30 * z,
            radius: 0.025,
        },
        1.0,
        emissive,
        plain(DVec3::new(1.0, 0.99, 0.93)),
    );
}

/// A stack of three books, each a little askew, spines to the front (−y).
fn books(parts: &mut Parts, rng: &mut ChaCha8Rng) {
    let top = f64::from(DEMO_TABLE_TOP_Z);
    let pages = DVec3::new(0.92, 0.89, 0.80);
    let books = [
        (
            0.0,
            0.0,
            0.12,
            0.085,
            0.035,
            8f64,
            DVec3::new(0.55, 0.10, 0.12),
        ),
        (
            0.005,
            -0.005,
            0.11,
            0.075,
            0.03,
            -5.0,
            DVec3::new(0.10, 0.15, 0.42),
        ),
        (
            -0.008,
            0.006,
            0.10,
            0.07,
            0.04,
            15.0,
            DVec3::new(0.14, 0.36, 0.20),
        ),
    ];
    let mut z0 = top;
    for (dx, dy, ha, hb, h, yaw, cover) in books {
        let cover = tinted(rng, cover);
        let faces = box_faces(
            DVec3::new(0.22 + dx, 0.15 + dy, z0),
            ha,
            hb,
            h,
            yaw.to_radians(),
        );
        for (k, face) in faces.into_iter().enumerate() {
            let (weight, paint): (f64, Paint) = match k {
                0 => (1.0, plain(cover)),
                1 => (0.2, plain(cover)),
                // The spine, with a gold band near each end.
                5 => (
                    1.0,
                    Box::new(move |_, u, _| {
                        if (0.1..0.16).contains(&u) || (0.84..0.9).contains(&u) {
                            DVec3::new(0.85, 0.70, 0.30)
                        } else {
                            cover
                        }
                    }),
                ),
                _ => (
                    1.0,
                    Box::new(move |_, _, v| pages * (0.93 + 0.07 * (v * PI).sin())),
                ),
            };
            parts.add(face, weight, MATTE, paint);
        }
        z0 += h;
    }
}

/// Potted plant on the floor beside the table, 40 cm tall.
fn plant(parts: &mut Parts, rng: &mut ChaCha8Rng) {
    let z = DVec3::Z;
    let c = DVec3::new(1.15, 0.75, 0.0);
    let terracotta = tinted(rng, DVec3::new(0.76, 0.40, 0.24));
    parts.add(
        upright(c, 0.08, 0.11, 0.18, false),
        1.0,
        MATTE,
        plain(terracotta),
    );
    parts.add(
        upright(c + 0.15 * z, 0.1033, 0.1067, 0.03, true),
        1.0,
        MATTE,
        plain(terracotta * 0.8),
    );
    parts.add(
        flat_ring(c + 0.15 * z, 0.0, 0.1033, false),
        1.0,
        MATTE,
        plain(DVec3::new(0.24, 0.16, 0.10)),
    );
    let leaf_green = tinted(rng, DVec3::new(0.20, 0.52, 0.15));
    let leaf_look = Look {
        light: Light::TwoSided,
        ..MATTE
    };
    for k in 0..16 {
        // Golden-angle yaws and spread pitches give an even, natural crown; steeper leaves
        // are longer, as inner leaves of a real plant are.
        let kf = k as f64;
        let yaw = kf * 2.399_963 + 0.3;
        let steep = (kf * 0.618_034).fract();
        let pitch = (30.0 + 50.0 * steep).to_radians();
        let length = 0.18 + 0.16 * steep;
        let radial = DVec3::new(yaw.cos(), yaw.sin(), 0.0);
        let dir = pitch.cos() * radial + pitch.sin() * z;
        let side = DVec3::new(-yaw.sin(), yaw.cos(), 0.0);
        let tone = 0.8 + 0.35 * hash01(k, 5);
        parts.add(
            Shape::Leaf {
                base: c + 0.15 * z + 0.02 * radial,
                dir,
                side,
                length,
                half_width: 0.045,
                droop: 0.2,
            },
            1.0,
            leaf_look,
            Box::new(move |_, u, _| {
                // A paler midrib down the leaf's centre.
                let rib = if (u - 0.5).abs() < 0.05 { 1.3 } else { 1.0 };
                leaf_green * tone * rib
            }),
        );
    }
}

/// Glass of water, 7 cm wide, 11 cm tall, two-thirds full; semi-transparent.
fn glass_of_water(parts: &mut Parts, rng: &mut ChaCha8Rng) {
    let x = DVec3::X;
    let y = DVec3::Y;
    let z = DVec3::Z;
    let top = f64::from(DEMO_TABLE_TOP_Z);
    let c = DVec3::new(-0.05, 0.22, top);
    let glass = Look {
        opacity: Opacity::Range(0.08, 0.3),
        sh: 0.15,
        light: Light::Diffuse,
        noise: 1.0,
    };
    let water = Look {
        opacity: Opacity::Range(0.15, 0.4),
        sh: 0.08,
        light: Light::Diffuse,
        noise: 1.0,
    };
    let glass_tint = tinted(rng, DVec3::new(0.84, 0.91, 0.95));
    let water_tint = tinted(rng, DVec3::new(0.45, 0.66, 0.86));
    parts.add(
        upright(c, 0.035, 0.037, 0.11, false),
        1.0,
        glass,
        plain(glass_tint),
    );
    parts.add(
        flat_ring(c + 0.004 * z, 0.0, 0.035, false),
        1.0,
        Look {
            opacity: Opacity::Range(0.3, 0.6),
            ..glass
        },
        plain(glass_tint),
    );
    parts.add(
        upright(c + 0.006 * z, 0.0335, 0.0347, 0.069, false),
        1.0,
        water,
        plain(water_tint),
    );
    parts.add(
        flat_ring(c + 0.075 * z, 0.0, 0.0347, false),
        1.0,
        Look {
            opacity: Opacity::Range(0.35, 0.65),
            ..water
        },
        plain(water_tint * 1.1),
    );
    parts.add(
        Shape::Torus {
            center: c + 0.11 * z,
            e1: x,
            e2: y,
            major: 0.037,
            minor: 0.0015,
            a0: 0.0,
            a1: TAU,
        },
        4.0,
        Look {
            opacity: Opacity::Range(0.4, 0.7),
            ..glass
        },
        plain(DVec3::splat(0.95)),
    );
}
