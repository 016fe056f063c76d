//! `"method": {"name": "auto", …}` (contract §5): a budget of time or error instead of a
//! method — its fields checked here, what was chosen recorded with the job's result.

use serde::{Deserialize, Serialize};

use super::MethodSpec;
use crate::error::{JobError, JobResult};

/// The method name that asks penumbra to choose.
pub const AUTO: &str = "auto";

/// What an `auto` job asks for: at least one of a time and an error.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AutoBudget {
    /// The render's wall time, milliseconds.
    pub max_ms: Option<f64>,
    /// The mean |V − Vref| over the penumbra, in (0, 1).
    pub max_error: Option<f64>,
}

impl AutoBudget {
    /// The budget of an `auto` method spec; `None` for any other method. Refuses unknown
    /// fields, budgets that are not finite and positive, an error outside (0, 1) and a spec
    /// with neither (each naming its field). The time's floor and ceiling need the device's
    /// model and the deadline: the server checks them.
    pub fn of(method: &MethodSpec) -> JobResult<Option<Self>> {
        if method.name != AUTO {
            return Ok(None);
        }
        let mut budget = Self::default();
        for (key, value) in &method.params {
            let field = format!("method.{key}");
            let number = || value.as_f64().filter(|v| v.is_finite()).ok_or_else(|| JobError::invalid(&field, "must be a finite number"));
            match key.as_str() {
                "max_ms" => {
                    let ms = number()?;
                    if ms <= 0.0 {
                        return Err(JobError::invalid(field, "must be a finite number of milliseconds > 0"));
                    }
                    budget.max_ms = Some(ms);
                }
                "max_error" => {
                    let error = number()?;
                    if !(error > 0.0 && error < 1.0) {
                        return Err(JobError::invalid(field, "must be in (0, 1): a mean |V − Vref| over the penumbra"));
                    }
                    budget.max_error = Some(error);
                }
                _ => return Err(JobError::field(crate::error::ErrorCode::UnknownField, field, "auto takes max_ms and max_error only")),
            }
        }
        if budget.max_ms.is_none() && budget.max_error.is_none() {
            return Err(JobError::invalid("method.max_ms", "auto needs a budget: max_ms, max_error or both"));
        }
        Ok(Some(budget))
    }
}

/// A predicted render: its wall time and its mean penumbra error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Prediction {
    pub ms: f64,
    pub error: f64,
}

/// What `auto` chose for a job, as its answer, record and headers say it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AutoChoice {
    /// The method and parameters rendered.
    pub method: MethodSpec,
    /// The same as `eval` writes it (`reference:samples=64`).
    pub label: String,
    pub predicted: Prediction,
    /// Which model predicted it: `measured` on this device, or the shipped `default`.
    pub model: String,
    /// The render's wall time, once rendered.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured_ms: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn spec(value: serde_json::Value) -> MethodSpec {
        serde_json::from_value(value).unwrap()
    }

    #[test]
    fn budgets_are_checked_with_their_field_named() {
        let cases = [
            (json!({"name": "auto"}), "method.max_ms"),
            (json!({"name": "auto", "max_ms": 0}), "method.max_ms"),
            (json!({"name": "auto", "max_ms": -3}), "method.max_ms"),
            (json!({"name": "auto", "max_ms": "fast"}), "method.max_ms"),
            (json!({"name": "auto", "max_error": 0}), "method.max_error"),
            (json!({"name": "auto", "max_error": 1}), "method.max_error"),
            (json!({"name": "auto", "max_error": 0.01, "samples": 3}), "method.samples"),
        ];
        for (value, field) in cases {
            let error = AutoBudget::of(&spec(value.clone())).unwrap_err();
            assert_eq!(error.field.as_deref(), Some(field), "{value}");
        }
        let both = AutoBudget::of(&spec(json!({"name": "auto", "max_ms": 250.5, "max_error": 0.02}))).unwrap().unwrap();
        assert_eq!(both, AutoBudget { max_ms: Some(250.5), max_error: Some(0.02) });
        assert_eq!(AutoBudget::of(&spec(json!({"name": "hard"}))).unwrap(), None);
    }
}
