//! Method parameters (contract §2): what a method declares — type, default, range, the
//! operator's cap that bounds it — and the checked values a job carries. A method reads a
//! value through the typed handle it declared (`Param<f32>`, `Param<u32>`, `Param<bool>`,
//! a `Choice` enum), so no read names a parameter by a string or asks for the wrong type, and
//! every `match` on a choice is exhaustive.

use std::collections::BTreeMap;
use std::marker::PhantomData;

use serde::Serialize;
use serde_json::{Map, Value};

use crate::error::{ErrorCode, JobError, JobResult};

/// The type, default and range of one method parameter.
#[derive(Debug, Clone, Copy, Serialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum ParamKind {
    Float { default: f64, min: f64, max: f64 },
    Integer { default: i64, min: i64, max: i64 },
    Boolean { default: bool },
    Choice { default: &'static str, options: &'static [&'static str] },
}

/// An operator limit that bounds a parameter beyond the method's own range
/// (`--max-samples`, `--max-rounds`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cap {
    /// Samples per pixel (`--max-samples`).
    Samples,
    /// Rounds of an iterative method (`--max-rounds`).
    Rounds,
}

/// One parameter as a method declares it and `GET /v1/methods` lists it.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ParamSpec {
    pub name: &'static str,
    #[serde(flatten)]
    pub kind: ParamKind,
    pub doc: &'static str,
    /// The operator limit that also bounds it, if any.
    #[serde(skip)]
    pub cap: Option<Cap>,
}

/// A typed handle on a parameter: its declaration, and the Rust type its value reads as.
#[derive(Debug, Clone, Copy)]
pub struct Param<T> {
    pub spec: ParamSpec,
    value: PhantomData<fn() -> T>,
}

impl<T> Param<T> {
    const fn new(name: &'static str, kind: ParamKind, doc: &'static str) -> Self {
        Self { spec: ParamSpec { name, kind, doc, cap: None }, value: PhantomData }
    }

    pub const fn name(&self) -> &'static str {
        self.spec.name
    }
}

impl Param<f32> {
    pub const fn float(name: &'static str, default: f64, min: f64, max: f64, doc: &'static str) -> Self {
        Self::new(name, ParamKind::Float { default, min, max }, doc)
    }
}

impl Param<u32> {
    pub const fn integer(name: &'static str, default: i64, min: i64, max: i64, doc: &'static str) -> Self {
        Self::new(name, ParamKind::Integer { default, min, max }, doc)
    }

    /// The same parameter, bounded also by an operator limit.
    pub const fn capped(mut self, cap: Cap) -> Self {
        self.spec.cap = Some(cap);
        self
    }
}

impl Param<bool> {
    pub const fn boolean(name: &'static str, default: bool, doc: &'static str) -> Self {
        Self::new(name, ParamKind::Boolean { default }, doc)
    }
}

/// A parameter whose value is one of a few named options, read as an enum: declare it with
/// `choice!`. The default is the first option.
pub trait Choice: Copy + 'static {
    /// The options as a job spells them, the default first.
    const NAMES: &'static [&'static str];
    /// The options, in the order of `NAMES`.
    const VALUES: &'static [Self];
}

/// Declares an enum whose variants are a parameter's options, each with its name in a job:
/// `choice! { pub enum Falloff { Linear = "linear", Sine = "sine" } }`. The first is the
/// default.
macro_rules! choice {
    ($(#[$meta:meta])* $vis:vis enum $name:ident { $($(#[$variant_meta:meta])* $variant:ident = $text:literal),+ $(,)? }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        $vis enum $name {
            $($(#[$variant_meta])* $variant),+
        }

        impl $crate::params::Choice for $name {
            const NAMES: &'static [&'static str] = &[$($text),+];
            const VALUES: &'static [Self] = &[$(Self::$variant),+];
        }
    };
}
pub(crate) use choice;

impl<T: Choice> Param<T> {
    pub const fn choice(name: &'static str, doc: &'static str) -> Self {
        Self::new(name, ParamKind::Choice { default: T::NAMES[0], options: T::NAMES }, doc)
    }
}

/// A checked parameter value.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum ParamValue {
    Float(f64),
    Integer(i64),
    Boolean(bool),
    Choice(&'static str),
}

/// The Rust types parameters read as.
pub trait ParamType: Sized {
    fn read(value: &ParamValue) -> Option<Self>;
    /// The declared default (the constructors of `Param<Self>` fix the kind).
    fn default_of(kind: &ParamKind) -> Self;
}

impl ParamType for f32 {
    fn read(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Float(x) => Some(*x as f32),
            ParamValue::Integer(x) => Some(*x as f32),
            _ => None,
        }
    }

    fn default_of(kind: &ParamKind) -> Self {
        match kind {
            ParamKind::Float { default, .. } => *default as f32,
            ParamKind::Integer { default, .. } => *default as f32,
            _ => 0.0,
        }
    }
}

impl ParamType for u32 {
    fn read(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Integer(x) => u32::try_from(*x).ok(),
            _ => None,
        }
    }

    fn default_of(kind: &ParamKind) -> Self {
        match kind {
            ParamKind::Integer { default, .. } => u32::try_from(*default).unwrap_or(0),
            _ => 0,
        }
    }
}

impl ParamType for bool {
    fn read(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Boolean(b) => Some(*b),
            _ => None,
        }
    }

    fn default_of(kind: &ParamKind) -> Self {
        matches!(kind, ParamKind::Boolean { default: true })
    }
}

impl<T: Choice> ParamType for T {
    fn read(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Choice(c) => T::NAMES.iter().position(|name| name == c).map(|i| T::VALUES[i]),
            _ => None,
        }
    }

    fn default_of(_: &ParamKind) -> Self {
        T::VALUES[0]
    }
}

/// Checked parameters: every declared parameter present, every value in range.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Params(BTreeMap<&'static str, ParamValue>);

impl Params {
    /// Checks the parameters a job gave against `specs`, filling in defaults. Unknown names
    /// are errors, not ignored (contract §2).
    pub fn parse(specs: &[ParamSpec], given: &Map<String, Value>) -> JobResult<Self> {
        if let Some(unknown) = given.keys().find(|k| !specs.iter().any(|s| s.name == k.as_str())) {
            let known: Vec<&str> = specs.iter().map(|s| s.name).collect();
            return Err(JobError::field(
                ErrorCode::UnknownField,
                format!("method.{unknown}"),
                format!(
                    "unknown parameter `{unknown}`; this method takes: {}",
                    if known.is_empty() { "none".into() } else { known.join(", ") }
                ),
            ));
        }
        let mut values = BTreeMap::new();
        for spec in specs {
            values.insert(spec.name, parse_one(spec, given.get(spec.name))?);
        }
        Ok(Self(values))
    }

    /// The value of a parameter the method declared; a parameter it did not declare (a
    /// programming error a test would catch) reads as its default rather than failing a job.
    pub fn get<T: ParamType>(&self, param: &Param<T>) -> T {
        self.0.get(param.spec.name).and_then(T::read).unwrap_or_else(|| T::default_of(&param.spec.kind))
    }

    /// Checked values by name, as integers where they are (for operator caps).
    pub fn integer(&self, name: &str) -> Option<i64> {
        match self.0.get(name) {
            Some(ParamValue::Integer(x)) => Some(*x),
            _ => None,
        }
    }
}

/// A JSON whole number, written `8` or `8.0`: JSON Schema counts both as an integer, and so
/// does the contract. None for a fraction, or a float too large to hold every integer.
pub fn whole_number(value: &Value) -> Option<i64> {
    value.as_i64().or_else(|| value.as_f64().filter(|x| x.fract() == 0.0 && x.abs() <= 2f64.powi(53)).map(|x| x as i64))
}

fn parse_one(spec: &ParamSpec, value: Option<&Value>) -> JobResult<ParamValue> {
    let field = || format!("method.{}", spec.name);
    Ok(match (spec.kind, value) {
        (ParamKind::Float { default, .. }, None) => ParamValue::Float(default),
        (ParamKind::Float { min, max, .. }, Some(v)) => match v.as_f64() {
            Some(x) if x.is_finite() && (min..=max).contains(&x) => ParamValue::Float(x),
            _ => return Err(JobError::invalid(field(), format!("must be a number in [{min}, {max}]"))),
        },
        (ParamKind::Integer { default, .. }, None) => ParamValue::Integer(default),
        (ParamKind::Integer { min, max, .. }, Some(v)) => match whole_number(v) {
            Some(x) if (min..=max).contains(&x) => ParamValue::Integer(x),
            _ => return Err(JobError::invalid(field(), format!("must be an integer in [{min}, {max}]"))),
        },
        (ParamKind::Boolean { default }, None) => ParamValue::Boolean(default),
        (ParamKind::Boolean { .. }, Some(v)) => match v.as_bool() {
            Some(b) => ParamValue::Boolean(b),
            None => return Err(JobError::invalid(field(), "must be true or false")),
        },
        (ParamKind::Choice { default, .. }, None) => ParamValue::Choice(default),
        (ParamKind::Choice { options, .. }, Some(v)) => match v.as_str().and_then(|s| options.iter().find(|o| **o == s)) {
            Some(option) => ParamValue::Choice(option),
            None => return Err(JobError::invalid(field(), format!("must be one of: {}", options.join(", ")))),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const BIAS: Param<f32> = Param::float("bias", 1.0, 0.0, 10.0, "");
    const ROUNDS: Param<u32> = Param::integer("rounds", 6, 1, 12, "").capped(Cap::Rounds);
    choice! {
        enum Mode { Adaptive = "adaptive", Fixed = "fixed" }
    }
    const MODE: Param<Mode> = Param::choice("mode", "");
    const SPECS: &[ParamSpec] = &[BIAS.spec, ROUNDS.spec, MODE.spec];

    fn given(json: &str) -> Map<String, Value> {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn defaults_and_ranges() {
        let p = Params::parse(SPECS, &given(r#"{"rounds": 3}"#)).unwrap();
        assert_eq!((p.get(&BIAS), p.get(&ROUNDS), p.get(&MODE)), (1.0, 3, Mode::Adaptive));
        let p = Params::parse(SPECS, &given(r#"{"mode": "fixed"}"#)).unwrap();
        assert_eq!(p.get(&MODE), Mode::Fixed);
        assert!(matches!(MODE.spec.kind, ParamKind::Choice { default: "adaptive", options: &["adaptive", "fixed"] }));
        assert_eq!(ROUNDS.spec.cap, Some(Cap::Rounds));
        let err = Params::parse(SPECS, &given(r#"{"rounds": 13}"#)).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("method.rounds"));
        let err = Params::parse(SPECS, &given(r#"{"bias": "x"}"#)).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("method.bias"));
        let err = Params::parse(SPECS, &given(r#"{"mode": "other"}"#)).unwrap_err();
        assert_eq!(err.field.as_deref(), Some("method.mode"));
        let err = Params::parse(SPECS, &given(r#"{"radius": 1}"#)).unwrap_err();
        assert_eq!((err.code, err.field.as_deref()), (ErrorCode::UnknownField, Some("method.radius")));
    }

    #[test]
    fn an_undeclared_parameter_reads_as_its_default() {
        const OTHER: Param<bool> = Param::boolean("other", true, "");
        let p = Params::parse(SPECS, &Map::new()).unwrap();
        assert!(p.get(&OTHER));
    }
}
