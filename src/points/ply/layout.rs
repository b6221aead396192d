//! Where the vertex element's properties go (see [`super`]): `x y z` required, `nx ny nz` and
//! `red green blue` all three or none, `alpha` optional, each into its channel; every other
//! property stepped over.

use super::header::{Element, Kind, Scalar};
use super::CHANNELS;

/// Where the vertex element's properties go.
#[derive(Debug)]
pub(super) struct Layout {
    /// Per property, the channel it fills, or `None` when it is stepped over.
    pub(super) slots: Vec<Option<usize>>,
    pub(super) normals: bool,
    /// The types of red, green, blue and (when given) alpha, when the vertices have colours.
    pub(super) colours: Option<[Option<Scalar>; 4]>,
}

impl Layout {
    /// The layout of `vertices`, or why its properties cannot be read as points.
    pub(super) fn new(vertices: &Element) -> std::result::Result<Layout, String> {
        let mut types = [None; CHANNELS.len()];
        let mut slots = Vec::with_capacity(vertices.properties.len());
        for property in &vertices.properties {
            let channel = CHANNELS.iter().position(|&c| c == property.name);
            if let Some(channel) = channel {
                let Kind::Scalar(scalar) = property.kind else {
                    return Err(format!(
                        "the vertex property `{}` is a list; it must be a single number",
                        property.name
                    ));
                };
                types[channel] = Some(scalar);
            }
            slots.push(channel);
        }
        let [x, y, z, nx, ny, nz, red, green, blue, alpha] = types;
        for (name, ty) in [("x", x), ("y", y), ("z", z)] {
            if ty.is_none() {
                return Err(format!("the vertex element has no `{name}` property"));
            }
        }
        let complete = |set: [Option<Scalar>; 3], names: &str| match set.iter().flatten().count() {
            0 => Ok(false),
            3 => Ok(true),
            _ => Err(format!(
                "the vertex element has only some of `{names}`: give all three or none"
            )),
        };
        let normals = complete([nx, ny, nz], "nx ny nz")?;
        let has_colours = complete([red, green, blue], "red green blue")?;
        if alpha.is_some() && !has_colours {
            return Err("the vertex element has `alpha` but no `red green blue`".into());
        }
        for (name, ty) in [
            ("red", red),
            ("green", green),
            ("blue", blue),
            ("alpha", alpha),
        ] {
            if let Some(ty) =
                ty.filter(|&t| !matches!(t, Scalar::UChar | Scalar::Float | Scalar::Double))
            {
                return Err(format!(
                    "the vertex colour `{name}` is {}: colours must be uchar (0–255) or float/double (0–1)",
                    ty.name()
                ));
            }
        }
        Ok(Layout {
            slots,
            normals,
            colours: has_colours.then_some([red, green, blue, alpha]),
        })
    }
}
