//! A box of named parameters: the start of a bounded fit, its bounds, and each parameter's
//! name and unit, in vector order.

/// Named parameters with their start values and bounds (`lower < upper`, infinite allowed).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ParamBox {
    /// Name and unit of each parameter.
    pub names: Vec<(String, String)>,
    /// Start values.
    pub start: Vec<f64>,
    /// Lower bounds.
    pub lower: Vec<f64>,
    /// Upper bounds.
    pub upper: Vec<f64>,
}

impl ParamBox {
    /// Appends one parameter.
    pub fn push(&mut self, name: String, unit: &str, start: f64, lower: f64, upper: f64) {
        self.names.push((name, unit.to_string()));
        self.start.push(start);
        self.lower.push(lower);
        self.upper.push(upper);
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.start.len()
    }

    /// Whether there is no parameter.
    pub fn is_empty(&self) -> bool {
        self.start.is_empty()
    }
}
