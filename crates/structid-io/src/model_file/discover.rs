//! The `[discover]` section of a nominal model ([`DiscoverSpec`]): declared candidate locations
//! and named states for `structid discover`.

use serde::Deserialize;
use structid_core::{Lft, Site};
use toml::Spanned;

use super::lft::Dim;
use super::source::{Source, check_unique_name, err_at, plural};
use crate::error::IoError;

/// A candidate location declared in `[discover]`: a block reading z row `z` and writing
/// w column `w` of the nominal model's LFT.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeclaredLocationSpec {
    /// Its name (unique, not empty, not the key of a built-in location), e.g. `spring`.
    pub name: String,
    /// The z row the block reads (< n_z).
    pub z: usize,
    /// The w column the block writes (< n_w).
    pub w: usize,
}

/// A state of the nominal model's LFT named in `[discover]` for localisation.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NamedStateSpec {
    /// Its name (unique, not empty), e.g. `velocity`.
    pub name: String,
    /// The state's index in the LFT (< n).
    pub state: usize,
}

/// The `[discover]` section: what a nominal model (a file without `[[nonlinearity]]` blocks)
/// declares for `structid discover`, in file order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DiscoverSpec {
    /// Extra candidate locations of the missing block, besides the built-in ones.
    pub locations: Vec<DeclaredLocationSpec>,
    /// Named states, offered as candidate signals when localising an effect.
    pub states: Vec<NamedStateSpec>,
}

/// The keys of the built-in discovery locations; a declared location may not take one of
/// these names (nor `declared-<i>`), since `structid discover --locations` accepts both.
pub const BUILT_IN_LOCATIONS: &[&str] = &["input", "output", "output-feedback", "rate-feedback"];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDiscover {
    #[serde(default)]
    locations: Vec<Spanned<RawLocation>>,
    #[serde(default)]
    states: Vec<Spanned<RawState>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLocation {
    name: Spanned<String>,
    z: Spanned<i64>,
    w: Spanned<i64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawState {
    name: Spanned<String>,
    state: Spanned<i64>,
}

/// Whether `name` has the form `declared-<i>`, the key of the i-th declared location.
fn is_declared_key(name: &str) -> bool {
    name.strip_prefix("declared-")
        .is_some_and(|i| !i.is_empty() && i.bytes().all(|b| b.is_ascii_digit()))
}

/// The `[discover]` section, checked against the LFT: indices in range, names unique and not
/// empty, each location once and a valid single-block LFT.
pub(super) fn parse_discover(
    raw: &RawDiscover,
    lft: &Lft,
    dz: &Dim,
    dw: &Dim,
    src: &Source<'_>,
) -> Result<DiscoverSpec, IoError> {
    let index = |v: &Spanned<i64>, key: &str, owner: &str| -> Result<(usize, usize), IoError> {
        let line = src.line(v.span().start);
        let i = *v.get_ref();
        usize::try_from(i).map(|i| (i, line)).map_err(|_| {
            err_at(
                line,
                format!("{owner}: {key} = {i} is negative; indices start at 0"),
            )
        })
    };
    let name_of = |v: &Spanned<String>, what: &str| -> Result<(String, usize), IoError> {
        let line = src.line(v.span().start);
        let name = v.get_ref().trim().to_string();
        if name.is_empty() {
            return Err(err_at(
                line,
                format!("a [discover] {what} has an empty name"),
            ));
        }
        Ok((name, line))
    };

    let mut out = DiscoverSpec::default();
    let mut lines: Vec<usize> = Vec::new();
    for entry in &raw.locations {
        let entry_line = src.line(entry.span().start);
        let r = entry.get_ref();
        let (name, name_line) = name_of(&r.name, "location")?;
        if BUILT_IN_LOCATIONS.contains(&name.as_str()) || is_declared_key(&name) {
            return Err(err_at(
                name_line,
                format!(
                    "the [discover] location `{name}` has the name of a built-in location key \
                     ({}, declared-<i>); choose another name",
                    BUILT_IN_LOCATIONS.join(", ")
                ),
            ));
        }
        let earlier = out.locations.iter().position(|l| l.name == name);
        check_unique_name("[discover] locations", &name, name_line, earlier, &lines)?;
        let owner = format!("[discover] location `{name}`");
        let (z, z_line) = index(&r.z, "z", &owner)?;
        if z >= dz.value {
            let what = format!("{owner} reads z row {z}");
            return Err(dz.out_of_range(z_line, &what, "z row"));
        }
        let (w, w_line) = index(&r.w, "w", &owner)?;
        if w >= dw.value {
            let what = format!("{owner} writes w column {w}");
            return Err(dw.out_of_range(w_line, &what, "w column"));
        }
        if let Some(j) = out.locations.iter().position(|l| l.z == z && l.w == w) {
            return Err(err_at(
                entry_line,
                format!(
                    "[discover] locations `{}` (line {}) and `{name}` are both z row {z} → w column \
                     {w}; declare each location once",
                    out.locations[j].name, lines[j]
                ),
            ));
        }
        // Safety net: the core builds the block's LFT from the same indices.
        Site::Declared { z, w }
            .insert(lft)
            .map_err(|e| err_at(entry_line, format!("{owner}: {e}")))?;
        out.locations.push(DeclaredLocationSpec { name, z, w });
        lines.push(entry_line);
    }

    let n = lft.dims().states;
    let mut lines: Vec<usize> = Vec::new();
    for entry in &raw.states {
        let r = entry.get_ref();
        let (name, name_line) = name_of(&r.name, "state")?;
        let earlier = out.states.iter().position(|s| s.name == name);
        check_unique_name("[discover] states", &name, name_line, earlier, &lines)?;
        let owner = format!("[discover] state `{name}`");
        let (state, state_line) = index(&r.state, "state", &owner)?;
        if state >= n {
            return Err(err_at(
                state_line,
                format!(
                    "{owner} is state {state} but the model has {} (indices 0…)",
                    plural(n, "state")
                ),
            ));
        }
        out.states.push(NamedStateSpec { name, state });
        lines.push(name_line);
    }
    Ok(out)
}
