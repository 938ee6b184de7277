//! Writing a model file back to TOML, in canonical form ([`ModelFile::to_toml_string`]).

use std::fmt::Write as _;

use nalgebra::DMatrix;
use structid_core::{GraphInterpolation, Lft, Site};

use super::{DiscoverSpec, DispersionSpec, LinearSpec, ModelFile, TruthSpec};
use crate::data_file::format_number;

impl ModelFile {
    /// The model file in canonical form. Parsing the text (with the same base directory for
    /// truth tables) gives back the same [`Lft`], signals, blocks and `[discover]` section. A
    /// continuous-time file is written in its discretised form.
    pub fn to_toml_string(&self) -> String {
        let mut s = String::new();
        let d = self.lft.dims();
        let _ = writeln!(
            s,
            "# structid model file: known linear block (discrete time), signal names, unknown static maps.\n\
             # n = {} states, n_u = {}, n_e = {}, n_w = {}, n_y = {}, n_z = {}.",
            d.states, d.u, d.e, d.w, d.y, d.z
        );
        if let Some(lin) = &self.linear {
            write_linear(&mut s, lin);
        } else {
            write_lft(&mut s, &self.lft);
        }
        s.push_str("\n[signals]\n");
        let _ = writeln!(s, "u = {}", string_list(&self.signals.u));
        let _ = writeln!(s, "y = {}", string_list(&self.signals.y));
        if let Some(z) = &self.signals.z {
            let _ = writeln!(s, "z = {}", string_list(z));
        }
        if let Some(d) = &self.discover {
            write_discover(&mut s, d);
        }
        for b in &self.blocks {
            s.push_str("\n[[nonlinearity]]\n");
            let _ = writeln!(s, "name = {}", toml_string(&b.name));
            let _ = writeln!(
                s,
                "inputs = [{}]",
                b.inputs
                    .iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            let _ = writeln!(s, "output = {}", b.output);
            // Written whatever the block, so that a file read back refuses a shape where a
            // model file would.
            if let Some(shape) = b.shape {
                let _ = writeln!(s, "shape = {}", toml_string(shape.as_str()));
            }
            if let Some(op) = &b.operator {
                let _ = writeln!(s, "operator = {}", op.to_toml());
                continue;
            }
            match &b.dispersion {
                DispersionSpec::Gaussian { sigma: None } => {
                    s.push_str("dispersion = { kind = \"gaussian\" }   # sigma = 0.1 × range of the block's z\n");
                }
                other => {
                    let _ = writeln!(
                        s,
                        "dispersion = {{ {} }}",
                        dispersion_keys_toml(other).join(", ")
                    );
                }
            }
            match &b.truth {
                Some(TruthSpec::Expression(e)) => {
                    let _ = writeln!(s, "truth = {}", toml_string(e));
                }
                Some(TruthSpec::Table { file, .. }) => {
                    let _ = writeln!(s, "truth = {{ table = {} }}", toml_string(file));
                }
                Some(TruthSpec::Family {
                    expression,
                    parameters,
                }) => {
                    let _ = writeln!(s, "truth = {}", toml_string(expression));
                    let values: Vec<String> = parameters
                        .iter()
                        .map(|(n, v)| format!("{n} = {}", format_number(*v)))
                        .collect();
                    let _ = writeln!(s, "parameters = {{ {} }}", values.join(", "));
                }
                None => {}
            }
        }
        s
    }
}

fn write_lft(s: &mut String, lft: &Lft) {
    let m = lft.matrices();
    s.push_str("[lft]\n");
    if let Some(ts) = lft.sample_time() {
        let _ = writeln!(s, "sample_time = {}", format_number(ts));
    }
    for (name, mat) in [
        ("A", &m.a),
        ("Bu", &m.bu),
        ("Be", &m.be),
        ("Bw", &m.bw),
        ("Cy", &m.cy),
        ("Dyu", &m.dyu),
        ("Dye", &m.dye),
        ("Dyw", &m.dyw),
        ("Cz", &m.cz),
        ("Dzu", &m.dzu),
        ("Dze", &m.dze),
        ("Dzw", &m.dzw),
    ] {
        let _ = writeln!(s, "{name} = {}", matrix_toml(mat));
    }
}

fn write_discover(s: &mut String, d: &DiscoverSpec) {
    s.push_str("\n[discover]\n");
    if !d.locations.is_empty() {
        s.push_str("locations = [   # a block reading z row `z` and writing w column `w`\n");
        for l in &d.locations {
            let _ = writeln!(
                s,
                "  {{ name = {}, z = {}, w = {} }},",
                toml_string(&l.name),
                l.z,
                l.w
            );
        }
        s.push_str("]\n");
    }
    if !d.states.is_empty() {
        s.push_str("states = [   # states of the LFT named for localisation\n");
        for st in &d.states {
            let _ = writeln!(
                s,
                "  {{ name = {}, state = {} }},",
                toml_string(&st.name),
                st.state
            );
        }
        s.push_str("]\n");
    }
}

fn write_linear(s: &mut String, lin: &LinearSpec) {
    let list = |v: &[f64]| {
        format!(
            "[{}]",
            v.iter()
                .map(|x| format_number(*x))
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    s.push_str("[linear]\n");
    let _ = writeln!(s, "structure = {}", toml_string(lin.structure_name()));
    if let Some(ts) = lin.model.sample_time {
        let _ = writeln!(s, "sample_time = {}", format_number(ts));
    }
    let _ = writeln!(s, "den = {}", list(&lin.model.den));
    let n_u = match lin.structure {
        Some(Site::OutputFeedback) => lin.model.num.len() - 1,
        _ => lin.model.num.len(),
    };
    let _ = writeln!(
        s,
        "num = [{}]",
        lin.model.num[..n_u]
            .iter()
            .map(|b| list(b))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if lin.separate_numerator {
        let _ = writeln!(s, "num_w = {}", list(&lin.model.num[n_u]));
    }
}

/// The `key = value` pairs of a dispersion's inline table, `kind` first.
fn dispersion_keys_toml(spec: &DispersionSpec) -> Vec<String> {
    let mut parts = vec![format!("kind = \"{}\"", spec.kind())];
    let sigma = |parts: &mut Vec<String>, sigma: &Option<f64>| {
        if let Some(sg) = sigma {
            parts.push(format!("sigma = {}", format_number(*sg)));
        }
    };
    match spec {
        DispersionSpec::Gaussian { sigma: sg } => sigma(&mut parts, sg),
        DispersionSpec::TotalVariation {
            neighbours,
            interpolation,
        } => {
            if let Some(k) = neighbours {
                parts.push(format!("neighbours = {k}"));
            }
            match interpolation {
                Some(GraphInterpolation::Nearest) => {
                    parts.push("interpolation = \"nearest\"".into())
                }
                Some(GraphInterpolation::InverseDistance) => {
                    parts.push("interpolation = \"inverse-distance\"".into())
                }
                None => {}
            }
        }
        DispersionSpec::LowRankGaussian {
            sigma: sg,
            tolerance,
        } => {
            sigma(&mut parts, sg);
            if let Some(t) = tolerance {
                parts.push(format!("tolerance = {}", format_number(*t)));
            }
        }
        DispersionSpec::Fourier {
            sigma: sg,
            harmonics,
            additive,
        } => {
            sigma(&mut parts, sg);
            if let Some(n) = harmonics {
                parts.push(format!("harmonics = {n}"));
            }
            if *additive {
                parts.push("combine = \"additive\"".into());
            }
        }
        DispersionSpec::Polynomial { degree, scale } => {
            parts.push(format!("degree = {degree}"));
            if let Some(sc) = scale {
                parts.push(format!("scale = {}", format_number(*sc)));
            }
        }
        DispersionSpec::WithTrend {
            kernel,
            degree,
            scale,
        } => {
            parts = dispersion_keys_toml(kernel);
            parts.push(match scale {
                Some(sc) => format!(
                    "trend = {{ degree = {degree}, scale = {} }}",
                    format_number(*sc)
                ),
                None => format!("trend = {degree}"),
            });
        }
    }
    parts
}

fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

fn string_list(v: &[String]) -> String {
    format!(
        "[{}]",
        v.iter()
            .map(|s| toml_string(s))
            .collect::<Vec<_>>()
            .join(", ")
    )
}

fn matrix_toml(m: &DMatrix<f64>) -> String {
    if m.nrows() == 0 {
        return "[]".into();
    }
    let row = |i: usize| {
        format!(
            "[{}]",
            (0..m.ncols())
                .map(|j| format_number(m[(i, j)]))
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    if m.nrows() == 1 {
        return format!("[{}]", row(0));
    }
    let mut s = String::from("[\n");
    for i in 0..m.nrows() {
        let _ = writeln!(s, "  {},", row(i));
    }
    s.push(']');
    s
}
