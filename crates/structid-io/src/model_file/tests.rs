use std::sync::Arc;

use structid_core::{GraphInterpolation, Site};
use structid_linear::PolynomialModel;

use super::*;

/// The canonical block of the specification, verbatim.
const CANONICAL: &str = r#"[lft]                      # discrete-time realisation of the known block, paper eq. (7)
sample_time = 1.0          # optional
A = [[0.5]]                # n×n ; an empty list [] when n = 0
Bu = [[1.0]]
Be = [[0.0]]
Bw = [[1.0]]
Cy = [[1.0]]
Dyu = [[0.0]]
Dye = [[1.0]]
Dyw = [[0.0]]
Cz = [[0.0]]
Dzu = [[1.0]]
Dze = [[0.0]]
Dzw = [[0.0]]

[signals]
u = ["u0"]                 # CSV column names of the known inputs, in order
y = ["y0"]                 # CSV column names of the measured outputs, in order
# z = ["z0"]               # optional: measured z columns; otherwise z is computed from u and y

[[nonlinearity]]
name = "f"
inputs = [0]               # indices into z
output = 0                 # index into w
dispersion = { kind = "gaussian", sigma = 0.4 }
truth = "tanh(z0)"         # optional, used by `simulate` and for error reports
"#;

fn err(text: &str) -> String {
    ModelFile::parse(text, None).unwrap_err().to_string()
}

#[test]
fn canonical_form_parses_exactly_as_written() {
    let m = ModelFile::parse(CANONICAL, None).unwrap();
    let d = m.lft.dims();
    assert_eq!((d.states, d.u, d.e, d.w, d.y, d.z), (1, 1, 1, 1, 1, 1));
    assert_eq!(m.lft.sample_time(), Some(1.0));
    let mm = m.lft.matrices();
    assert_eq!(mm.a[(0, 0)], 0.5);
    assert_eq!(mm.bw[(0, 0)], 1.0);
    assert_eq!(mm.dye[(0, 0)], 1.0);
    assert_eq!(mm.dzu[(0, 0)], 1.0);
    assert_eq!(m.signals.u, ["u0"]);
    assert_eq!(m.signals.y, ["y0"]);
    assert_eq!(m.signals.z, None);
    assert_eq!(
        m.blocks,
        vec![BlockSpec {
            name: "f".into(),
            inputs: vec![0],
            output: 0,
            dispersion: DispersionSpec::Gaussian { sigma: Some(0.4) },
            truth: Some(TruthSpec::Expression("tanh(z0)".into())),
            operator: None,
            shape: None,
        }]
    );
    let truth = m.truth_maps().unwrap().unwrap();
    assert!((truth[0].eval(&[0.3]) - 0.3f64.tanh()).abs() < 1e-15);
    let model = m.to_model(None, None).unwrap();
    assert_eq!(
        model.blocks()[0].dispersion.describe(),
        "gaussian(sigma=0.4)"
    );
}

#[test]
fn empty_matrices_for_zero_states() {
    let text = r#"
[lft]
A = []
Bu = []
Be = []
Bw = []
Cy = []
Dyu = [[0.0]]
Dye = [[1.0]]
Dyw = [[1.0, 1.0]]
Cz = []
Dzu = [[1.0], [0.5]]
Dze = [[0.0], [0.0]]
Dzw = [[0.0, 0.0], [0.0, 0.0]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "a"
inputs = [0]
output = 0

[[nonlinearity]]
name = "b"
inputs = [1, 0]
output = 1
dispersion = { kind = "gaussian" }
"#;
    let m = ModelFile::parse(text, None).unwrap();
    let d = m.lft.dims();
    assert_eq!((d.states, d.u, d.e, d.w, d.y, d.z), (0, 1, 1, 2, 1, 2));
    assert_eq!(m.lft.matrices().cy.shape(), (1, 0));
    assert_eq!(m.lft.matrices().cz.shape(), (2, 0));
    assert_eq!(
        m.blocks[0].dispersion,
        DispersionSpec::Gaussian { sigma: None }
    );
    // Default sigma needs data.
    let e = m.to_model(None, None).unwrap_err().to_string();
    assert!(e.contains("block `a`") && e.contains("sigma"), "{e}");
    let z = Signal::from_channels(&[vec![0.0, 2.0, 1.0], vec![-5.0, 5.0, 0.0]]).unwrap();
    let model = m.to_model(None, Some(&z)).unwrap();
    assert_eq!(
        model.blocks()[0].dispersion.describe(),
        "gaussian(sigma=0.2)"
    );
    assert_eq!(model.blocks()[1].dispersion.describe(), "gaussian(sigma=1)");
    let model = m.to_model(Some(0.7), None).unwrap();
    assert_eq!(
        model.blocks()[1].dispersion.describe(),
        "gaussian(sigma=0.7)"
    );
    assert!(m.to_model(Some(-1.0), None).is_err());
    assert!(m.to_model(Some(f64::NAN), None).is_err());
    // Omitted matrices are zero.
    let short = "[lft]\nDye = [[1.0]]\nDyw = [[1.0]]\nDzu = [[1.0]]\n[signals]\nu = [\"u\"]\ny = [\"y\"]\n\
                 [[nonlinearity]]\nname = \"N\"\ninputs = [0]\noutput = 0\n";
    let m = ModelFile::parse(short, None).unwrap();
    assert_eq!(m.lft.dims().states, 0);
}

#[test]
fn dimension_errors_name_the_matrix_the_reason_and_the_line() {
    let bad = CANONICAL.replace("Bu = [[1.0]]", "Bu = [[1.0, 2.0]]");
    assert_eq!(
        err(&bad),
        "model file: matrix Bu has 2 columns but [signals].u names 1 input (line 4)"
    );
    let bad = CANONICAL.replace("Cy = [[1.0]]", "Cy = [[1.0], [2.0]]");
    let e = err(&bad);
    assert!(
        e.contains("matrix Cy has 2 rows but [signals].y names 1 output (line 7)"),
        "{e}"
    );
    let bad = CANONICAL.replace("Bw = [[1.0]]", "Bw = [[1.0], [1.0]]");
    let e = err(&bad);
    assert!(
        e.contains("matrix Bw has 2 rows but A is 1×1") && e.contains("(line 6)"),
        "{e}"
    );
    let bad = CANONICAL.replace("Dye = [[1.0]]", "Dye = [[1.0, 0.0]]");
    let e = err(&bad);
    assert!(
        e.contains("matrix Dye has 2 columns but Be has 1 column") && e.contains("(line 9)"),
        "{e}"
    );
    let bad = CANONICAL.replace("A = [[0.5]]", "A = [[0.5, 0.1]]");
    let e = err(&bad);
    assert!(e.contains("square") && e.contains("(line 3)"), "{e}");
    let bad = CANONICAL.replace("A = [[0.5]]", "A = [[0.5, 0.1], [0.2]]");
    let e = err(&bad);
    assert!(
        e.contains("row 2 has 1 entry but row 1 has 2 entries") && e.contains("line 3"),
        "{e}"
    );
    let bad = CANONICAL.replace("Bu = [[1.0]]", "Bu = []");
    let e = err(&bad);
    assert!(
        e.contains("matrix Bu is empty but must be 1×1") && e.contains("line 4"),
        "{e}"
    );
    let bad = CANONICAL.replace("Bu = [[1.0]]", "Bu = [[nan]]");
    let e = err(&bad);
    assert!(e.contains("non-finite") && e.contains("line 4"), "{e}");
    let bad = CANONICAL.replace("u = [\"u0\"]", "u = [\"u0\", \"u1\"]");
    let e = err(&bad);
    assert!(
        e.contains("matrix Bu has 1 column but [signals].u names 2 inputs (line 4)"),
        "{e}"
    );
}

#[test]
fn block_errors_name_the_line() {
    let bad = CANONICAL.replace("inputs = [0]", "inputs = [1]");
    let e = err(&bad);
    assert!(
        e.contains("block `f` reads z[1]") && e.contains("(line 23)"),
        "{e}"
    );
    let bad = CANONICAL.replace("output = 0 ", "output = 3 ");
    let e = err(&bad);
    assert!(e.contains("writes w[3]") && e.contains("(line 24)"), "{e}");
    let bad = format!("{CANONICAL}\n[[nonlinearity]]\nname = \"f\"\ninputs = [0]\noutput = 0\n");
    let e = err(&bad);
    assert!(
        e.contains("two [[nonlinearity]] blocks are named `f`") && e.contains("line 29"),
        "{e}"
    );
    let bad = format!("{CANONICAL}\n[[nonlinearity]]\nname = \"g\"\ninputs = [0]\noutput = 0\n");
    let e = err(&bad);
    assert!(
        e.contains("both write w[0]") && e.contains("line 31"),
        "{e}"
    );
    let bad = format!(
        "{}\n[[nonlinearity]]\nname = \"g\"\ninputs = [0]\noutput = 0\n",
        CANONICAL
            .replace("Bw = [[1.0]]", "Bw = [[1.0, 0.5]]")
            .replace("Dyw = [[0.0]]", "Dyw = [[0.0, 0.0]]")
            .replace("Dzw = [[0.0]]", "Dzw = [[0.0, 0.0]]")
            .split("[[nonlinearity]]")
            .next()
            .unwrap()
    );
    let e = err(&bad);
    assert!(
        e.contains("w[1] is not produced by any block") && e.contains("[discover]"),
        "{e}"
    );
    let bad = CANONICAL.replace("tanh(z0)", "tanh(z1)");
    let e = err(&bad);
    assert!(
        e.contains("truth of block `f`") && e.contains("z1") && e.contains("line 26"),
        "{e}"
    );
    let bad = CANONICAL.replace("inputs = [0]", "inputs = []");
    assert!(err(&bad).contains("empty"));
    let bad = CANONICAL.replace("inputs = [0]", "inputs = [-1]");
    assert!(err(&bad).contains("negative"));
}

#[test]
fn toml_syntax_errors_give_line_and_column() {
    let bad = CANONICAL.replace("Dyw = [[0.0]]", "Dyw = [[0.0]");
    let e = err(&bad);
    assert!(e.starts_with("model file: invalid TOML"), "{e}");
    assert!(e.contains("(line 11, column 1)"), "{e}");
    assert!(e.contains("after `Dyw = [[0.0]`"), "{e}");
    let bad = CANONICAL.replace("sample_time = 1.0", "sample_time = \"fast\"");
    let e = err(&bad);
    assert!(e.contains("line 2"), "{e}");
    let bad = CANONICAL.replace("Dzw = [[0.0]]", "Dzw = [[0.0]]\nBz = [[1.0]]");
    let e = err(&bad);
    assert!(e.contains("Bz") && e.contains("line 15"), "{e}");
    let e = err("[signals]\nu = [\"u\"]\ny = [\"y\"]\n");
    assert!(e.contains("neither [lft]") && e.contains("[linear]"), "{e}");
}

#[test]
fn unknown_dispersion_kind_lists_supported_kinds() {
    let bad = CANONICAL.replace("kind = \"gaussian\"", "kind = \"laplace\"");
    let e = err(&bad);
    assert!(
        e.contains("unknown dispersion kind `laplace`") && e.contains("supported kinds: gaussian"),
        "{e}"
    );
    assert!(e.contains("(line 25)"), "{e}");
    let bad = CANONICAL.replace("sigma = 0.4", "sigma = -0.4");
    assert!(err(&bad).contains("greater than zero"));
    let bad = CANONICAL.replace("sigma = 0.4", "sgima = 0.4");
    assert!(err(&bad).contains("unknown key `sgima`"));
    let ok = CANONICAL.replace("sigma = 0.4", "sigma = 1");
    let m = ModelFile::parse(&ok, None).unwrap();
    assert_eq!(m.blocks[0].dispersion.sigma(), Some(1.0));
}

#[test]
fn signals_are_checked() {
    let bad = CANONICAL.replace("y = [\"y0\"]", "y = []");
    assert!(err(&bad).contains("names no measured output"));
    let bad = CANONICAL.replace("# z = [\"z0\"]", "z = [\"z0\", \"z1\"]");
    let e = err(&bad);
    assert!(
        e.contains("[signals].z names 2 columns") && e.contains("line 19"),
        "{e}"
    );
    let ok = CANONICAL.replace("# z = [\"z0\"]", "z = [\"zm\"]");
    let m = ModelFile::parse(&ok, None).unwrap();
    assert_eq!(m.z_names(), ["zm"]);
    let bad = CANONICAL.replace("u = [\"u0\"]", "u = [\"a\", \"a\"]");
    assert!(err(&bad).contains("twice"));
}

#[test]
fn round_trip_through_to_toml_string() {
    let m = ModelFile::parse(CANONICAL, None).unwrap();
    let text = m.to_toml_string();
    let back = ModelFile::parse(&text, None).unwrap();
    assert_eq!(back.lft, m.lft);
    assert_eq!(back.blocks, m.blocks);
    assert_eq!(back.signals, m.signals);

    // A bigger model with awkward numbers, n = 0 matrices and measured z.
    let text = r#"
[lft]
A = []
Dye = [[1.0], [0.0]]
Dyw = [[1.0, 0.1], [0.0, 1.0]]
Dyu = [[0.1, 3.0e-17], [1e300, -0.0]]
Dzu = [[1.0, 0.0], [0.0, 1.0]]
[signals]
u = ["u \"quoted\"", "u2"]
y = ["y1", "y2"]
z = ["z a", "z\\b"]
[[nonlinearity]]
name = "first map"
inputs = [1, 0]
output = 1
dispersion = { kind = "gaussian" }
[[nonlinearity]]
name = "g"
inputs = [0]
output = 0
dispersion = { kind = "gaussian", sigma = 0.123456789012345 }
truth = "0.5*(sin((3*z0)^2) + (2*z0)^2 - 2)"
"#;
    let m = ModelFile::parse(text, None).unwrap();
    let back = ModelFile::parse(&m.to_toml_string(), None).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.lft.matrices().dyu[(0, 1)], 3.0e-17);
}

#[test]
fn continuous_time_is_discretised_by_zoh() {
    let text = r#"
[lft]
time = "continuous"
sample_time = 0.1
A = [[-1.0]]
Bu = [[0.0]]
Be = [[0.0]]
Bw = [[1.0]]
Cy = [[1.0]]
Dye = [[1.0]]
Dzu = [[1.0]]
[signals]
u = ["u"]
y = ["y"]
[[nonlinearity]]
name = "N"
inputs = [0]
output = 0
"#;
    let m = ModelFile::parse(text, None).unwrap();
    let mm = m.lft.matrices();
    assert!((mm.a[(0, 0)] - (-0.1f64).exp()).abs() < 1e-14);
    assert!((mm.bw[(0, 0)] - (1.0 - (-0.1f64).exp())).abs() < 1e-14);
    assert_eq!(mm.cy[(0, 0)], 1.0);
    assert_eq!(m.lft.sample_time(), Some(0.1));
    let e = err(&text.replace("sample_time = 0.1\n", ""));
    assert!(
        e.contains("needs a sample_time") && e.contains("line 3"),
        "{e}"
    );
    let e = err(&text.replace("continuous", "analog"));
    assert!(e.contains("not supported"), "{e}");
}

#[test]
fn truth_tables_are_read_relative_to_the_model_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("f.csv"), "z,value\n-1,1\n0,0\n1,1\n").unwrap();
    let text = CANONICAL.replace("truth = \"tanh(z0)\"", "truth = { table = \"f.csv\" }");
    let path = dir.path().join("m.toml");
    std::fs::write(&path, &text).unwrap();
    let m = ModelFile::from_path(&path).unwrap();
    let t = m.truth_maps().unwrap().unwrap();
    assert_eq!(t[0].eval(&[0.5]), 0.5);
    // Round trip keeps the table reference.
    let back = ModelFile::parse(&m.to_toml_string(), Some(dir.path())).unwrap();
    assert_eq!(back.blocks, m.blocks);
    // The block-level `table` key is accepted too.
    let alt = CANONICAL.replace("truth = \"tanh(z0)\"", "table = \"f.csv\"");
    let m2 = ModelFile::parse(&alt, Some(dir.path())).unwrap();
    assert_eq!(m2.blocks, m.blocks);
    // Missing file: line of the key and the file name.
    let missing = CANONICAL.replace("truth = \"tanh(z0)\"", "truth = { table = \"nope.csv\" }");
    std::fs::write(&path, &missing).unwrap();
    let e = ModelFile::from_path(&path).unwrap_err().to_string();
    assert!(
        e.contains("nope.csv") && e.contains("line 26") && e.contains("m.toml"),
        "{e}"
    );
}

#[test]
fn no_panics_on_odd_input() {
    for text in [
        "",
        "[lft]",
        "[lft]\n[signals]\ny=[\"y\"]",
        "[lft]\nA=[[1]]\n[signals]\ny=[\"y\"]",
        "[lft]\nA=[[]]\n[signals]\ny=[\"y\"]",
        "[lft]\nA=[1]\n[signals]\ny=[\"y\"]",
        "[lft]\nA=[[1e400]]\n[signals]\ny=[\"y\"]",
        "[lft]\nDzw=[[1]]\nDyw=[[1]]\n[signals]\ny=[\"y\"]\n[[nonlinearity]]\nname=\"n\"\ninputs=[0]\noutput=0\ndispersion=3",
        "[lft]\nDzw=[[1]]\nDyw=[[1]]\n[signals]\ny=[\"y\"]\n[[nonlinearity]]\nname=\"n\"\ninputs=[0]\noutput=99999999999999",
        "[lft]\nDzw=[[1]]\nDyw=[[1]]\n[signals]\ny=[\"y\"]\n[[nonlinearity]]\nname=\"n\"\ninputs=[0]\noutput=0\ntruth=3",
        "[lft]\nDzw=[[1]]\nDyw=[[1]]\n[signals]\ny=[\"y\"]\n[[nonlinearity]]\nname=\"ü\"\ninputs=0\noutput=0\ntruth=\"(\"",
    ] {
        let _ = ModelFile::parse(text, None);
    }
    // A valid model with an algebraic loop parses (identification does not need D_zw = 0).
    let text = "[lft]\nDye=[[1]]\nDzw=[[1]]\nDyw=[[1]]\nDzu=[[1]]\n[signals]\nu=[\"u\"]\ny=[\"y\"]\n\
                [[nonlinearity]]\nname=\"n\"\ninputs=0\noutput=0\n";
    let m = ModelFile::parse(text, None).unwrap();
    assert!(m.lft.check_no_algebraic_loop().is_err());
}

#[test]
fn fourier_dispersion_parses_builds_and_round_trips() {
    let text = CANONICAL.replace(
        r#"dispersion = { kind = "gaussian", sigma = 0.4 }"#,
        r#"dispersion = { kind = "fourier", sigma = 0.3, harmonics = 24, combine = "additive" }"#,
    );
    let m = ModelFile::parse(&text, None).unwrap();
    assert_eq!(
        m.blocks[0].dispersion,
        DispersionSpec::Fourier {
            sigma: Some(0.3),
            harmonics: Some(24),
            additive: true
        }
    );
    assert_eq!(m.blocks[0].dispersion.kind(), "fourier");
    let d = m.blocks[0].dispersion.build(None, None).unwrap();
    assert!(d.describe().starts_with("fourier"), "{}", d.describe());
    let back = ModelFile::parse(&m.to_toml_string(), None).unwrap();
    assert_eq!(back.blocks, m.blocks);
    // Bad keys and values name the block and the line.
    for (bad, needle) in [
        (r#"{ kind = "fourier", harmonics = 0 }"#, "harmonics"),
        (r#"{ kind = "fourier", combine = "product" }"#, "combine"),
        (
            r#"{ kind = "fourier", width = 1.0 }"#,
            "unknown key `width`",
        ),
        (r#"{ kind = "fourier", sigma = -1.0 }"#, "sigma"),
    ] {
        let t = CANONICAL.replace(r#"{ kind = "gaussian", sigma = 0.4 }"#, bad);
        let e = err(&t);
        assert!(e.contains(needle) && e.contains("line"), "{bad}: {e}");
    }
}

#[test]
fn low_rank_gaussian_dispersion_parses_builds_and_round_trips() {
    let text = CANONICAL.replace(
        r#"dispersion = { kind = "gaussian", sigma = 0.4 }"#,
        r#"dispersion = { kind = "gaussian-lowrank", sigma = 0.4, tolerance = 1e-6 }"#,
    );
    let m = ModelFile::parse(&text, None).unwrap();
    assert_eq!(
        m.blocks[0].dispersion,
        DispersionSpec::LowRankGaussian {
            sigma: Some(0.4),
            tolerance: Some(1e-6)
        }
    );
    let d = m.blocks[0].dispersion.build(None, None).unwrap();
    assert!(
        d.describe().starts_with("low-rank gaussian"),
        "{}",
        d.describe()
    );
    let back = ModelFile::parse(&m.to_toml_string(), None).unwrap();
    assert_eq!(back.blocks, m.blocks);
    let bad = CANONICAL.replace(
        r#"{ kind = "gaussian", sigma = 0.4 }"#,
        r#"{ kind = "gaussian-lowrank", tolerance = 2.0 }"#,
    );
    let e = err(&bad);
    assert!(e.contains("tolerance") && e.contains("line"), "{e}");
}

#[test]
fn total_variation_dispersion_parses_builds_and_round_trips() {
    for (written, expected) in [
        (
            r#"dispersion = { kind = "tv", neighbours = 5, interpolation = "nearest" }"#,
            DispersionSpec::TotalVariation {
                neighbours: Some(5),
                interpolation: Some(GraphInterpolation::Nearest),
            },
        ),
        (
            r#"dispersion = "tv""#,
            DispersionSpec::TotalVariation {
                neighbours: None,
                interpolation: None,
            },
        ),
    ] {
        let text = CANONICAL.replace(
            r#"dispersion = { kind = "gaussian", sigma = 0.4 }"#,
            written,
        );
        let m = ModelFile::parse(&text, None).unwrap();
        assert_eq!(m.blocks[0].dispersion, expected);
        assert_eq!(m.blocks[0].dispersion.kind(), "tv");
        assert_eq!(m.blocks[0].dispersion.sigma(), None);
        // No σ and no data are needed to build it.
        let d = m.blocks[0].dispersion.build(None, None).unwrap();
        assert!(d.describe().starts_with("tv"), "{}", d.describe());
        let back = ModelFile::parse(&m.to_toml_string(), None).unwrap();
        assert_eq!(back.blocks, m.blocks);
    }
    for (bad, needle) in [
        (r#"{ kind = "tv", neighbours = 0 }"#, "neighbours"),
        (
            r#"{ kind = "tv", interpolation = "cubic" }"#,
            "interpolation",
        ),
        (r#"{ kind = "tv", sigma = 0.3 }"#, "unknown key `sigma`"),
    ] {
        let t = CANONICAL.replace(r#"{ kind = "gaussian", sigma = 0.4 }"#, bad);
        let e = err(&t);
        assert!(e.contains(needle) && e.contains("line"), "{bad}: {e}");
    }
}

/// A Silverbox-like file: G = (0.1q⁻¹ + 0.05q⁻²)/(1 − 1.6q⁻¹ + 0.8q⁻²) in output feedback.
const LINEAR: &str = r#"[linear]
structure = "output-feedback"
sample_time = 0.5
den = [1.0, -1.6, 0.8]
num = [[0.0, 0.1, 0.05]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "stiffness"
inputs = [0]
output = 0
dispersion = { kind = "fourier", sigma = 0.2, trend = 3 }
"#;

#[test]
fn linear_section_is_the_output_feedback_lft_of_its_polynomials() {
    let m = ModelFile::parse(LINEAR, None).unwrap();
    let d = m.lft.dims();
    assert_eq!((d.states, d.u, d.w, d.y, d.z), (2, 1, 1, 1, 1));
    assert_eq!(m.lft.sample_time(), Some(0.5));
    let lin = m.linear.as_ref().unwrap();
    assert_eq!(lin.structure, Some(Site::OutputFeedback));
    assert!(!lin.separate_numerator);
    // The feedback path shares the numerator: w enters exactly like −u.
    let (tu, tw) = (
        m.lft.t_yu().markov_parameters(6),
        m.lft.t_yw().markov_parameters(6),
    );
    for (a, b) in tu.iter().zip(&tw) {
        assert!((a[(0, 0)] + b[(0, 0)]).abs() < 1e-15);
    }
    // The u path is G: its impulse response follows the difference equation.
    let h: Vec<f64> = tu.iter().map(|m| m[(0, 0)]).collect();
    let mut g = vec![0.0; 6];
    for k in 0..6 {
        let b = [0.0, 0.1, 0.05].get(k).copied().unwrap_or(0.0);
        g[k] = b + 1.6 * if k >= 1 { g[k - 1] } else { 0.0 }
            - 0.8 * if k >= 2 { g[k - 2] } else { 0.0 };
    }
    for (a, b) in h.iter().zip(&g) {
        assert!((a - b).abs() < 1e-12, "{h:?} vs {g:?}");
    }
    // z = y: measured, including the noise.
    assert_eq!(m.lft.matrices().dze[(0, 0)], 1.0);
    assert!(matches!(
        &m.blocks[0].dispersion,
        DispersionSpec::WithTrend { degree: 3, scale: None, kernel } if kernel.kind() == "fourier"
    ));
}

#[test]
fn linear_sections_and_trends_round_trip() {
    let separate = LINEAR.replace(
        "num = [[0.0, 0.1, 0.05]]",
        "num = [[0.0, 0.1, 0.05]]\nnum_w = [0.0, -0.2]",
    );
    let input = r#"[linear]
structure = "input"
den = [1.0, -0.5]
num = [[0.0, 2.0]]
[signals]
u = ["u"]
y = ["y"]
[[nonlinearity]]
name = "actuator"
inputs = [0]
output = 0
dispersion = { kind = "polynomial", degree = 5, scale = 2.5 }
"#;
    let lti = "[linear]\nstructure = \"lti\"\nden = [1.0, -0.5]\nnum = [[1.0, 2.0], [0.0, 1.0]]\n[signals]\nu = [\"a\", \"b\"]\ny = [\"y\"]\n";
    for text in [LINEAR, &separate, input, lti] {
        let m = ModelFile::parse(text, None).unwrap();
        let again = ModelFile::parse(&m.to_toml_string(), None).unwrap();
        assert_eq!(m, again, "{}", m.to_toml_string());
        assert!(m.to_toml_string().contains("[linear]"));
    }
    let m = ModelFile::parse(&separate, None).unwrap();
    assert!(m.linear.as_ref().unwrap().separate_numerator);
    assert_eq!(m.linear.as_ref().unwrap().model.num[1], vec![0.0, -0.2]);
    let m = ModelFile::parse(lti, None).unwrap();
    assert_eq!((m.lft.dims().w, m.lft.dims().z, m.lft.dims().u), (0, 0, 2));
    // The trend and polynomial dispersions build what they say.
    let m = ModelFile::parse(LINEAR, None).unwrap();
    let d = m.blocks[0].dispersion.build(None, None).unwrap();
    assert!(
        d.describe().contains("polynomial(degree=3"),
        "{}",
        d.describe()
    );
    assert_eq!(d.width(), Some(0.2));
}

#[test]
fn linear_section_errors_name_the_line() {
    let cases: [(String, &str, usize); 8] = [
        (
            LINEAR.replace("output-feedback", "feedforward"),
            "supported: \"output-feedback\", \"input\", \"output\", \"rate-feedback\", \"lti\"",
            2,
        ),
        (
            LINEAR.replace("num = [[0.0, 0.1, 0.05]]", "num = [[0.3, 0.1, 0.05]]"),
            "direct term",
            5,
        ),
        (
            LINEAR.replace("num = [[0.0, 0.1, 0.05]]", "num = [[0.0, 0.1], [0.0, 1.0]]"),
            "2 numerators",
            5,
        ),
        (
            LINEAR.replace("den = [1.0, -1.6, 0.8]", "den = [0.0, -1.6, 0.8]"),
            "nonzero first one",
            4,
        ),
        (
            LINEAR.replace(
                "num = [[0.0, 0.1, 0.05]]",
                "num = [[0.0, 0.1, 0.05]]\nnum_w = [0.1, 0.2]",
            ),
            "needs a delay",
            6,
        ),
        (
            LINEAR.replace("[signals]", "[lft]\nA = []\n[signals]"),
            "both [lft] and [linear]",
            1,
        ),
        (
            LINEAR.replace("trend = 3", "trend = { degree = 3, scale = -1.0 }"),
            "greater than zero",
            15,
        ),
        (
            LINEAR.replace("sample_time = 0.5", "sample_time = -0.5"),
            "sample_time",
            3,
        ),
    ];
    for (text, needle, line) in cases {
        let e = err(&text);
        assert!(e.contains(needle), "{e}");
        assert!(e.contains(&format!("line {line}")), "{e}");
    }
    let zeros = LINEAR.replace(
        "num = [[0.0, 0.1, 0.05]]",
        "num = [[0.0, 0.1, 0.05]]\nnum_w = [0.0, 0.0]",
    );
    let e = err(&zeros);
    assert!(
        e.contains("num_w is all zeros") && e.contains("line 6"),
        "{e}"
    );
    let zeros = LINEAR.replace("num = [[0.0, 0.1, 0.05]]", "num = [[0.0, 0.0]]");
    let e = err(&zeros);
    assert!(
        e.contains("num[0] is all zeros") && e.contains("line 5"),
        "{e}"
    );
    let lti_with_map = LINEAR.replace("output-feedback", "lti");
    assert!(err(&lti_with_map).contains("z[0]"));
}

/// G = (0.1q⁻¹ + 0.05q⁻²)/(1 − 1.6q⁻¹ + 0.8q⁻²) with a sensor map or in rate feedback.
fn sensor_or_rate(structure: &str) -> String {
    LINEAR
        .replace("output-feedback", structure)
        .replace("stiffness", "N")
}

/// The largest difference between the first `count` Markov parameters of two LFTs (all paths).
fn markov_distance(a: &Lft, b: &Lft, count: usize) -> f64 {
    let (ha, hb) = (
        a.state_space().markov_parameters(count),
        b.state_space().markov_parameters(count),
    );
    assert_eq!(ha.len(), hb.len());
    ha.iter()
        .zip(&hb)
        .map(|(x, y)| {
            assert_eq!(x.shape(), y.shape());
            (x - y).abs().max()
        })
        .fold(0.0, f64::max)
}

#[test]
fn output_and_rate_feedback_structures_parse_to_the_builders_lfts() {
    let g = PolynomialModel {
        num: vec![vec![0.0, 0.1, 0.05]],
        den: vec![1.0, -1.6, 0.8],
        sample_time: Some(0.5),
    };
    let d: Arc<dyn structid_core::Dispersion> =
        Arc::new(structid_core::PolynomialDispersion::new(3).unwrap());
    for (name, kind, builder) in [
        (
            "output",
            Site::Output,
            (|g, d| structid_core::Structure::wiener(g, d))
                as fn(
                    &PolynomialModel,
                    Arc<dyn structid_core::Dispersion>,
                ) -> structid_core::Structure,
        ),
        ("rate-feedback", Site::RateFeedback, |g, d| {
            structid_core::Structure::rate_feedback(g, d)
        }),
    ] {
        let text = sensor_or_rate(name);
        let m = ModelFile::parse(&text, None).unwrap();
        let lin = m.linear.as_ref().unwrap();
        assert_eq!(lin.structure, Some(kind));
        assert_eq!(parse_linear_structure(name), Some(Some(kind)));
        assert_eq!(lin.model, g, "{name}: num is G's numerator of u");
        assert!(!lin.separate_numerator);
        assert!(lin.refinable());
        assert_eq!(lin.structure("N").map(|s| s.site()), Some(kind));
        let expected = builder(&g, Arc::clone(&d)).lft().unwrap();
        assert_eq!(m.lft.dims(), expected.dims(), "{name}");
        assert_eq!(m.lft.sample_time(), Some(0.5));
        let d = markov_distance(&m.lft, &expected, 12);
        assert!(d == 0.0, "{name}: impulse responses differ by {d}");
        let (dims, blocks) = (m.lft.dims(), m.to_model(None, None).unwrap());
        assert_eq!((dims.u, dims.y, dims.w, dims.z), (1, 1, 1, 1));
        assert_eq!(blocks.blocks().len(), 1);
        // z is computed, never read: G·u for the sensor, a dynamic Ψ for the rate.
        let source = m.lft.measurability().unwrap();
        match kind {
            Site::Output => {
                assert_eq!(source, structid_core::ZSource::InputOnly)
            }
            _ => assert!(matches!(source, structid_core::ZSource::Dynamic { .. })),
        }
        // The file writes back as read.
        let again = ModelFile::parse(&m.to_toml_string(), None).unwrap();
        assert_eq!(m, again, "{}", m.to_toml_string());
        assert!(
            m.to_toml_string()
                .contains(&format!("structure = \"{name}\""))
        );
    }
    // The sensor path: y = w + e and z = G·u, whose impulse response is G's.
    let m = ModelFile::parse(&sensor_or_rate("output"), None).unwrap();
    let g_ss = g.to_state_space().unwrap();
    let (hz, hg) = (m.lft.t_zu().markov_parameters(8), g_ss.markov_parameters(8));
    for (a, b) in hz.iter().zip(&hg) {
        assert!((a[(0, 0)] - b[(0, 0)]).abs() < 1e-15);
    }
    assert_eq!(m.lft.matrices().dyw[(0, 0)], 1.0);
}

#[test]
fn output_and_rate_feedback_errors_name_the_line() {
    // Rate feedback needs the delay (num is on line 5).
    let direct = sensor_or_rate("rate-feedback")
        .replace("num = [[0.0, 0.1, 0.05]]", "num = [[0.3, 0.1, 0.05]]");
    let e = err(&direct);
    assert!(
        e.contains("direct term") && e.contains("rate feedback") && e.contains("line 5"),
        "{e}"
    );
    // The sensor map does not need one.
    let sensor_direct =
        sensor_or_rate("output").replace("num = [[0.0, 0.1, 0.05]]", "num = [[0.3, 0.1, 0.05]]");
    assert!(ModelFile::parse(&sensor_direct, None).is_ok());
    for name in ["output", "rate-feedback"] {
        // Several inputs: the error points at [linear] (line 1).
        let two = sensor_or_rate(name)
            .replace("u = [\"u\"]", "u = [\"u\", \"v\"]")
            .replace("num = [[0.0, 0.1, 0.05]]", "num = [[0.0, 0.1], [0.0, 1.0]]");
        let e = err(&two);
        assert!(
            e.contains(&format!("structure = \"{name}\" has one input u"))
                && e.contains("2 inputs")
                && e.contains("line 1"),
            "{name}: {e}"
        );
        // Two numerators for one input (line 5).
        let e = err(&sensor_or_rate(name)
            .replace("num = [[0.0, 0.1, 0.05]]", "num = [[0.0, 0.1], [0.0, 1.0]]"));
        assert!(
            e.contains("2 numerators") && e.contains("line 5"),
            "{name}: {e}"
        );
        // num_w belongs to output feedback (line 6).
        let e = err(&sensor_or_rate(name).replace(
            "num = [[0.0, 0.1, 0.05]]",
            "num = [[0.0, 0.1, 0.05]]\nnum_w = [0.0, -0.2]",
        ));
        assert!(
            e.contains("only applies to structure = \"output-feedback\"") && e.contains("line 6"),
            "{name}: {e}"
        );
        // z is fixed by the structure ([signals].z is on line 10).
        let e = err(&sensor_or_rate(name).replace("y = [\"y\"]", "y = [\"y\"]\nz = [\"z\"]"));
        assert!(
            e.contains("[signals].z is not used") && e.contains("line 10"),
            "{name}: {e}"
        );
    }
}

/// A nominal model (no blocks) with two declared w columns and two z rows: a mass with
/// position and velocity states, spring and damper injection points.
const NOMINAL: &str = r#"[lft]
sample_time = 0.1
A = [[1.0, 0.1], [-0.2, 0.9]]
Bu = [[0.0], [0.1]]
Bw = [[0.0, 0.0], [-0.1, 0.1]]
Cy = [[1.0, 0.0]]
Dye = [[1.0]]
Cz = [[1.0, 0.0], [0.0, 1.0]]

[signals]
u = ["force"]
y = ["position"]

[discover]
locations = [
  { name = "spring", z = 0, w = 0 },
  { name = "damper", z = 1, w = 0 },
]
states = [{ name = "velocity", state = 1 }]
"#;

#[test]
fn discover_section_declares_locations_and_states_of_a_nominal_model() {
    let m = ModelFile::parse(NOMINAL, None).unwrap();
    let d = m.lft.dims();
    assert_eq!((d.states, d.u, d.e, d.w, d.y, d.z), (2, 1, 1, 2, 1, 2));
    assert!(m.blocks.is_empty());
    assert_eq!(
        m.discover,
        Some(DiscoverSpec {
            locations: vec![
                DeclaredLocationSpec {
                    name: "spring".into(),
                    z: 0,
                    w: 0
                },
                DeclaredLocationSpec {
                    name: "damper".into(),
                    z: 1,
                    w: 0
                },
            ],
            states: vec![NamedStateSpec {
                name: "velocity".into(),
                state: 1
            }],
        })
    );
    // The core model of a nominal file: no blocks, the declared w columns dropped, z kept.
    let model = m.to_model(None, None).unwrap();
    assert!(model.blocks().is_empty());
    let md = model.lft().dims();
    assert_eq!((md.states, md.w, md.z), (2, 0, 2));
    assert_eq!(model.lft().sample_time(), Some(0.1));
    assert_eq!(model.lft().matrices().a, m.lft.matrices().a);
    // The array-of-tables spelling is the same section.
    let long = NOMINAL.split("[discover]").next().unwrap().to_string()
        + "[[discover.locations]]\nname = \"spring\"\nz = 0\nw = 0\n\n\
           [[discover.locations]]\nname = \"damper\"\nz = 1\nw = 0\n\n\
           [[discover.states]]\nname = \"velocity\"\nstate = 1\n";
    assert_eq!(ModelFile::parse(&long, None).unwrap(), m);
    // Without [discover] the nominal model with declared channels is accepted as well.
    let plain = NOMINAL.split("[discover]").next().unwrap();
    let p = ModelFile::parse(plain, None).unwrap();
    assert_eq!((p.discover, p.lft), (None, m.lft));
}

#[test]
fn nominal_model_without_blocks_keeps_its_unused_w_columns() {
    // The canonical block's LFT without its [[nonlinearity]]: w[0] is a declared injection point.
    let text = CANONICAL.split("[[nonlinearity]]").next().unwrap();
    let m = ModelFile::parse(text, None).unwrap();
    assert_eq!((m.lft.dims().w, m.lft.dims().z), (1, 1));
    assert!(m.blocks.is_empty() && m.discover.is_none());
    assert_eq!(m.to_model(None, None).unwrap().lft().dims().w, 0);
    let back = ModelFile::parse(&m.to_toml_string(), None).unwrap();
    assert_eq!(back, m);
    // A [linear] structure with a map still needs its block.
    let e = err(
        "[linear]\nstructure = \"input\"\nden = [1.0, -0.5]\nnum = [[0.0, 1.0]]\n\
                 [signals]\nu = [\"u\"]\ny = [\"y\"]\n",
    );
    assert!(
        e.contains("w[0] is not produced by any block") && !e.contains("[discover]"),
        "{e}"
    );
}

#[test]
fn discover_section_round_trips_through_to_toml_string() {
    let m = ModelFile::parse(NOMINAL, None).unwrap();
    let text = m.to_toml_string();
    assert!(text.contains("[discover]"), "{text}");
    let back = ModelFile::parse(&text, None).unwrap();
    assert_eq!(back, m);
    // Awkward names, only states, and an empty section.
    let odd = NOMINAL.replace("\"spring\"", "\"spring \\\"k\\\"\"");
    let m = ModelFile::parse(&odd, None).unwrap();
    assert_eq!(
        m.discover.as_ref().unwrap().locations[0].name,
        "spring \"k\""
    );
    assert_eq!(ModelFile::parse(&m.to_toml_string(), None).unwrap(), m);
    let states_only = NOMINAL.split("locations = [").next().unwrap().to_string()
        + "states = [{ name = \"position\", state = 0 }, { name = \"velocity\", state = 1 }]\n";
    let m = ModelFile::parse(&states_only, None).unwrap();
    assert_eq!(m.discover.as_ref().unwrap().states.len(), 2);
    assert_eq!(ModelFile::parse(&m.to_toml_string(), None).unwrap(), m);
    let empty = NOMINAL.split("locations = [").next().unwrap();
    let m = ModelFile::parse(empty, None).unwrap();
    assert_eq!(m.discover, Some(DiscoverSpec::default()));
    assert_eq!(ModelFile::parse(&m.to_toml_string(), None).unwrap(), m);
    // A [linear] lti model may name states of its realisation.
    let lti = "[linear]\nstructure = \"lti\"\nden = [1.0, -1.2, 0.5]\nnum = [[0.0, 0.3, 0.2]]\n\
               [signals]\nu = [\"u\"]\ny = [\"y\"]\n[discover]\nstates = [{ name = \"s1\", state = 1 }]\n";
    let m = ModelFile::parse(lti, None).unwrap();
    assert_eq!(m.discover.as_ref().unwrap().states[0].state, 1);
    assert_eq!(ModelFile::parse(&m.to_toml_string(), None).unwrap(), m);
}

#[test]
fn discover_errors_name_the_line() {
    let cases: &[(&str, &str, &[&str], usize)] = &[
        // (replace, with, message parts, line)
        (
            "{ name = \"spring\", z = 0, w = 0 }",
            "{ name = \"spring\", z = 2, w = 0 }",
            &[
                "[discover] location `spring` reads z row 2",
                "2 z rows",
                "Cz has 2 rows",
            ],
            16,
        ),
        (
            "{ name = \"damper\", z = 1, w = 0 }",
            "{ name = \"damper\", z = 1, w = 5 }",
            &["location `damper` writes w column 5", "2 w columns", "Bw"],
            17,
        ),
        (
            "state = 1 }",
            "state = 2 }",
            &["[discover] state `velocity` is state 2", "2 states"],
            19,
        ),
        (
            "z = 1, w = 0",
            "z = -1, w = 0",
            &["location `damper`: z = -1 is negative"],
            17,
        ),
        (
            "state = 1 }",
            "state = -3 }",
            &["state `velocity`: state = -3 is negative"],
            19,
        ),
        (
            "name = \"damper\"",
            "name = \" \"",
            &["a [discover] location has an empty name"],
            17,
        ),
        (
            "name = \"velocity\"",
            "name = \"\"",
            &["a [discover] state has an empty name"],
            19,
        ),
        (
            "name = \"damper\"",
            "name = \"spring\"",
            &["two [discover] locations are named `spring` (lines 16 and 17)"],
            17,
        ),
        (
            "states = [{ name = \"velocity\", state = 1 }]",
            "states = [\n{ name = \"v\", state = 1 },\n{ name = \"v\", state = 0 },\n]",
            &["two [discover] states are named `v` (lines 20 and 21)"],
            21,
        ),
        (
            "name = \"damper\"",
            "name = \"output-feedback\"",
            &["`output-feedback` has the name of a built-in location"],
            17,
        ),
        (
            "name = \"damper\"",
            "name = \"declared-0\"",
            &["`declared-0` has the name of a built-in location"],
            17,
        ),
        (
            "name = \"damper\", z = 1",
            "name = \"damper\", z = 0",
            &["locations `spring` (line 16) and `damper` are both z row 0 → w column 0"],
            17,
        ),
        (
            "states = [",
            "named = 1\nstates = [",
            &["unknown field `named`", "in `named = 1`"],
            19,
        ),
        (
            "z = 1, w = 0",
            "z = 1, w = 0, row = 3",
            &["unknown field `row`"],
            17,
        ),
        ("z = 1, w = 0", "z = 1", &["missing field `w`"], 17),
        ("z = 1, w = 0", "z = 1.5, w = 0", &["invalid TOML"], 17),
    ];
    for (from, to, parts, line) in cases {
        assert!(NOMINAL.contains(from), "{from}");
        let e = err(&NOMINAL.replacen(from, to, 1));
        for p in *parts {
            assert!(e.contains(p), "{to}: `{p}` not in: {e}");
        }
        assert!(
            e.contains(&format!("(line {line})")) || e.contains(&format!("(line {line}, ")),
            "{to}: not line {line}: {e}"
        );
    }

    // [discover] describes a nominal model: not with blocks.
    let with_block = format!(
        "{}\n[discover]\nstates = [{{ name = \"x\", state = 0 }}]\n",
        CANONICAL
    );
    let e = err(&with_block);
    assert!(
        e.contains("[discover] describes a nominal model")
            && e.contains("1 [[nonlinearity]] block (the first at line 21)")
            && e.contains("(line 28)"),
        "{e}"
    );
    // [linear] lti has no w column to declare a location on.
    let lti = "[linear]\nstructure = \"lti\"\nden = [1.0, -0.5]\nnum = [[0.0, 1.0]]\n\
               [signals]\nu = [\"u\"]\ny = [\"y\"]\n[discover]\n\
               locations = [{ name = \"k\", z = 0, w = 0 }]\n";
    let e = err(lti);
    assert!(
        e.contains("reads z row 0 but the model has 0 z rows")
            && e.contains("[linear] structure = \"lti\" has no map")
            && e.contains("(line 9)"),
        "{e}"
    );
}

#[test]
fn a_parametric_family_parses_evaluates_round_trips_and_its_errors_name_the_line() {
    let text = CANONICAL.replace(
        "truth = \"tanh(z0)\"         # optional, used by `simulate` and for error reports",
        "truth = \"k*tanh(z0/k) + c\"\nparameters = { k = 2, c = -0.25 }",
    );
    let m = ModelFile::parse(&text, None).unwrap();
    let Some(TruthSpec::Family { parameters, .. }) = &m.blocks[0].truth else {
        panic!("{:?}", m.blocks[0].truth)
    };
    // Sorted by name.
    assert_eq!(
        parameters,
        &[("c".to_string(), -0.25), ("k".to_string(), 2.0)]
    );
    let f = m.blocks[0].truth_map().unwrap().unwrap();
    assert!((f.eval(&[1.0]) - (2.0 * 0.5f64.tanh() - 0.25)).abs() < 1e-15);
    let again = ModelFile::parse(&m.to_toml_string(), None).unwrap();
    assert_eq!(again.blocks[0].truth, m.blocks[0].truth);

    let with = |params: &str| {
        CANONICAL.replace(
            "truth = \"tanh(z0)\"         # optional, used by `simulate` and for error reports",
            &format!("truth = \"k*tanh(z0)\"\n{params}"),
        )
    };
    // The expression's errors point at `truth` (line 26), the values' at `parameters` (27).
    for (bad, needle, line) in [
        (with("parameters = { c = 1.0 }"), "`k`", 26),
        (with("parameters = { k = 1.0, z0 = 2.0 }"), "`z0`", 26),
        (with("parameters = { k = \"big\" }"), "must be a number", 27),
        (with("parameters = {}"), "empty", 27),
        (with("parameters = [1.0]"), "must be a table", 27),
    ] {
        let e = err(&bad);
        assert!(
            e.contains(needle) && e.contains(&format!("line {line}")),
            "{needle}: {e}"
        );
    }
    let e = err(&CANONICAL.replace(
        "truth = \"tanh(z0)\"         # optional, used by `simulate` and for error reports",
        "parameters = { k = 1.0 }",
    ));
    assert!(
        e.contains("without a `truth`") && e.contains("line 26"),
        "{e}"
    );
    let e = err(&CANONICAL.replace(
        "truth = \"tanh(z0)\"         # optional, used by `simulate` and for error reports",
        "table = \"map.csv\"\nparameters = { k = 1.0 }",
    ));
    assert!(e.contains("not a table") && e.contains("line 27"), "{e}");
}

#[test]
fn a_shape_is_read_written_and_refused_where_it_cannot_hold() {
    let with = |line: &str| CANONICAL.replace("truth = \"tanh(z0)\"", line);
    let m = ModelFile::parse(&with("shape = \"decreasing\""), None).unwrap();
    assert_eq!(
        m.blocks[0].shape,
        Some(structid_core::Monotonicity::Decreasing)
    );
    let again = ModelFile::parse(&m.to_toml_string(), None).unwrap();
    assert_eq!(again.blocks, m.blocks);
    // Identification by the dispersion criterion fits unconstrained maps: it says so.
    let refused = m.to_model(None, None).unwrap_err().to_string();
    assert!(
        refused.contains("`shape`") && refused.contains("joint fit"),
        "{refused}"
    );

    let e = err(&with("shape = \"upwards\""));
    assert!(
        e.contains("line 26") && e.contains("unknown shape `upwards`"),
        "{e}"
    );
    let e = err(&with(
        "truth = \"k*z0\"\nparameters = { k = 1.0 }\nshape = \"increasing\"",
    ));
    assert!(e.contains("named family"), "{e}");
    let two = with("shape = \"increasing\"")
        .replace("Cz = [[0.0]]", "Cz = [[0.0], [1.0]]")
        .replace("Dzu = [[1.0]]", "Dzu = [[1.0], [0.0]]")
        .replace("Dze = [[0.0]]", "Dze = [[0.0], [0.0]]")
        .replace("Dzw = [[0.0]]", "Dzw = [[0.0], [0.0]]")
        .replace(
            "inputs = [0]               # indices into z",
            "inputs = [0, 1]",
        );
    let e = err(&two);
    assert!(e.contains("several inputs"), "{e}");
}
