//! A model file from a polynomial G and the sites of its blocks: the `[linear]` form for one
//! block (or none), the `[lft]` form of [`structid_core::Structure::then`] for several.

use std::sync::Arc;

use structid_core::{PolynomialDispersion, Site, Structure};
use structid_linear::PolynomialModel;

use super::{BlockSpec, DispersionSpec, LinearSpec, ModelFile, SignalNames};
use crate::error::IoError;

/// One block of a structure: its name, where it sits, its dispersion.
#[derive(Clone, Debug, PartialEq)]
pub struct SiteBlock {
    /// The block's name.
    pub name: String,
    /// Its site: the first in G, each further one around the model built so far.
    pub site: Site,
    /// Its dispersion.
    pub dispersion: DispersionSpec,
}

impl ModelFile {
    /// The model file of G = `g` with `blocks` placed in order (none: the linear model alone),
    /// reading the data columns `inputs` (one per numerator of `g`) and `output`.
    ///
    /// ```
    /// use structid_core::Site;
    /// use structid_io::{DispersionSpec, ModelFile, SiteBlock};
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: None };
    /// let block = |name: &str, site| SiteBlock { name: name.into(), site, dispersion: DispersionSpec::Gaussian { sigma: Some(0.3) } };
    /// let m = ModelFile::from_structure(&g, &[block("actuator", Site::Input), block("sensor", Site::Output)], vec!["u".into()], "y".into()).unwrap();
    /// assert_eq!((m.lft.dims().w, m.blocks[1].name.as_str()), (2, "sensor"));
    /// let one = ModelFile::from_structure(&g, &[block("N", Site::Input)], vec!["u".into()], "y".into()).unwrap();
    /// assert!(one.linear.is_some());
    /// ```
    ///
    /// # Errors
    /// A structure that cannot be built (see [`Structure::then`]), names that are not unique,
    /// and the model file's own checks.
    pub fn from_structure(
        g: &PolynomialModel,
        blocks: &[SiteBlock],
        inputs: Vec<String>,
        output: String,
    ) -> Result<ModelFile, IoError> {
        let signals = SignalNames {
            u: inputs,
            y: vec![output],
            z: None,
        };
        let specs: Vec<BlockSpec> = blocks
            .iter()
            .enumerate()
            .map(|(i, b)| BlockSpec {
                name: b.name.clone(),
                inputs: vec![i],
                output: i,
                dispersion: b.dispersion.clone(),
                truth: None,
                operator: None,
                shape: None,
            })
            .collect();
        let file = if blocks.len() <= 1 {
            let spec = LinearSpec::from_linear(g, blocks.first().map(|b| b.site));
            ModelFile {
                lft: spec.lft()?,
                linear: Some(spec),
                signals,
                blocks: specs,
                discover: None,
                path: None,
            }
        } else {
            // The dispersions do not shape the LFT; the blocks keep their own.
            let placeholder = Arc::new(PolynomialDispersion::new(1)?);
            let mut s = Structure::new(g, blocks[0].site, placeholder.clone());
            for b in &blocks[1..] {
                s = s.then(b.site, placeholder.clone());
            }
            s.model()?;
            ModelFile {
                lft: s.lft()?,
                linear: None,
                signals,
                blocks: specs,
                discover: None,
                path: None,
            }
        };
        // Through the text and back: every check of a model file applies.
        ModelFile::parse(&file.to_toml_string(), None)
    }
}
