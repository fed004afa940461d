//! The one table that says how layer names of other renderers map onto filtrace's layers.
//!
//! An EXR channel name is split at its LAST dot into a *prefix* and a *component*:
//! `ViewLayer.Denoising Albedo.R` → (`ViewLayer.Denoising Albedo`, `R`), `nn.X` → (`nn`, `X`),
//! a bare `R` → (``, `R`). A channel group (all channels sharing a prefix) answers a
//! lookup for a layer alias `a` when its prefix equals `a` or ends in `.a` (so Blender's
//! view-layer / render-layer names in front are ignored); comparisons ignore ASCII case.
//!
//! The group's channels are then picked by the alias's component sets, tried in order
//! (`R,G,B` then `X,Y,Z` ...). The bare group (prefix ``) only ever matches with the FIRST
//! component set, so that a plain RGB file's `R` is never taken for a depth.
//!
//! | filtrace layer | filtrace writes | also understood (Blender / Mitsuba 3 / others) |
//! |---|---|---|
//! | `color` | `R,G,B` | `Combined.*`, `Image.*`, `rgba.*`, `beauty.*`, `noisy.*` |
//! | `direct`, `indirect` | `direct.R/G/B`, ... | `direct_light`, `indirect_light` |
//! | `albedo` | `albedo.R/G/B` | `Denoising Albedo.*`, `DiffCol.*`, `diffuse_color` |
//! | `normal` | `normal.X/Y/Z` | `Normal.*`, `Denoising Normal.*`, Mitsuba `nn.*`, `sh_normal.*`, `geo_normal.*` |
//! | `position` | `position.X/Y/Z` | `Position.*`, `P.*`, `pos.*`, `world_position.*` |
//! | `depth` | `depth.Z` | `Depth.Z` (Blender), bare `Z`, Mitsuba `depth.T`, `dd.Y` |
//! | `variance` | `variance.R/G/B` | `var.*` |
//!
//! A name that is in no row (`filtered`, `importance`) matches its own prefix and takes
//! the group's channels in the order `R G B A X Y Z`, then alphabetically.

/// One filtrace layer and the names other files give it.
#[derive(Debug, Clone, Copy)]
pub struct LayerAlias {
    /// filtrace's name for the layer (what [`crate::ExrImage::layer`] is usually asked for).
    pub canonical: &'static str,
    /// The prefix filtrace itself writes (`""` for the colour's bare `R,G,B`).
    pub written_as: &'static str,
    /// Every prefix (or last prefix segment) that means this layer, best first.
    pub names: &'static [&'static str],
    /// Component names tried in order; all sets of one alias have the same length.
    pub components: &'static [&'static [&'static str]],
}

const RGB: &[&str] = &["R", "G", "B"];
const XYZ: &[&str] = &["X", "Y", "Z"];

/// The alias table. Order inside `names` is priority order.
pub const LAYER_ALIASES: &[LayerAlias] = &[
    LayerAlias {
        canonical: "color",
        written_as: "",
        names: &["", "color", "colour", "rgb", "rgba", "combined", "image", "beauty", "main", "noisy"],
        components: &[RGB],
    },
    LayerAlias {
        canonical: "direct",
        written_as: "direct",
        names: &["direct", "direct_light", "directlight"],
        components: &[RGB],
    },
    LayerAlias {
        canonical: "indirect",
        written_as: "indirect",
        names: &["indirect", "indirect_light", "indirectlight"],
        components: &[RGB],
    },
    LayerAlias {
        canonical: "albedo",
        written_as: "albedo",
        names: &["albedo", "denoising albedo", "diffcol", "diffuse_color", "diffuse color"],
        components: &[RGB],
    },
    LayerAlias {
        canonical: "normal",
        written_as: "normal",
        names: &[
            "normal",
            "normals",
            "denoising normal",
            "nn",
            "sh_normal",
            "shading_normal",
            "geo_normal",
            "n",
        ],
        components: &[XYZ, RGB],
    },
    LayerAlias {
        canonical: "position",
        written_as: "position",
        names: &["position", "pos", "p", "world_position", "worldposition"],
        components: &[XYZ, RGB],
    },
    LayerAlias {
        canonical: "depth",
        written_as: "depth",
        names: &["", "depth", "z", "dd", "distance"],
        components: &[&["Z"], &["T"], &["Y"], &["V"], &["R"]],
    },
    LayerAlias {
        canonical: "variance",
        written_as: "variance",
        names: &["variance", "var"],
        components: &[RGB],
    },
];

/// The alias row whose canonical name or one of whose names equals `name` (ASCII case
/// ignored). The empty name is the colour's bare `R,G,B`.
pub fn find_alias(name: &str) -> Option<&'static LayerAlias> {
    LAYER_ALIASES
        .iter()
        .find(|a| a.canonical.eq_ignore_ascii_case(name))
        .or_else(|| LAYER_ALIASES.iter().find(|a| a.names.iter().any(|n| n.eq_ignore_ascii_case(name))))
}

/// Splits a channel name at its last dot: `a.b.R` → (`a.b`, `R`), `R` → (``, `R`).
pub fn split_channel_name(name: &str) -> (&str, &str) {
    match name.rfind('.') {
        Some(i) => (&name[..i], &name[i + 1..]),
        None => ("", name),
    }
}

/// Whether a group prefix answers to alias name `alias`: equal, or ending in `.alias`.
pub fn prefix_matches(prefix: &str, alias: &str) -> bool {
    if alias.is_empty() {
        return prefix.is_empty();
    }
    if prefix.eq_ignore_ascii_case(alias) {
        return true;
    }
    prefix.len() > alias.len()
        && prefix.as_bytes()[prefix.len() - alias.len() - 1] == b'.'
        && prefix[prefix.len() - alias.len()..].eq_ignore_ascii_case(alias)
}

/// Order used for the channels of a layer that is in no alias row.
pub fn generic_component_rank(component: &str) -> usize {
    const ORDER: [&str; 7] = ["R", "G", "B", "A", "X", "Y", "Z"];
    ORDER.iter().position(|c| c.eq_ignore_ascii_case(component)).unwrap_or(ORDER.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_and_prefix_rules() {
        assert_eq!(split_channel_name("ViewLayer.Denoising Albedo.R"), ("ViewLayer.Denoising Albedo", "R"));
        assert_eq!(split_channel_name("R"), ("", "R"));
        assert!(prefix_matches("ViewLayer.Combined", "combined"));
        assert!(prefix_matches("nn", "nn"));
        assert!(!prefix_matches("ViewLayer.Combined", "ined"));
        assert!(!prefix_matches("xnn", "nn"));
        assert!(prefix_matches("", ""));
        assert!(!prefix_matches("albedo", ""));
    }

    #[test]
    fn every_alias_row_is_consistent() {
        for a in LAYER_ALIASES {
            assert!(!a.components.is_empty(), "{}", a.canonical);
            let n = a.components[0].len();
            assert!(a.components.iter().all(|c| c.len() == n), "{}", a.canonical);
            assert!(a.names.contains(&a.written_as), "{} must understand what it writes", a.canonical);
            assert_eq!(find_alias(a.canonical).unwrap().canonical, a.canonical);
        }
        assert_eq!(find_alias("Denoising Albedo").unwrap().canonical, "albedo");
        assert_eq!(find_alias("nn").unwrap().canonical, "normal");
        assert!(find_alias("filtered").is_none());
    }
}
