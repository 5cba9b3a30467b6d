//! A paper's published figures against a set-up model's: each figure either belongs to the part
//! the model's parameters were fitted on, or is predicted by the model without refitting.
use serde::Serialize;

/// Which part of a paper's figures a comparison belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Part {
    /// The model's parameters were fitted on this figure (among others).
    Fit,
    /// The model predicts this figure from parameters fitted on others.
    Prediction,
}

impl Part {
    pub fn as_str(self) -> &'static str {
        match self {
            Part::Fit => "fit",
            Part::Prediction => "prediction",
        }
    }
}

/// The band a figure must fall in: a share of the paper's figure, and a floor in the figure's
/// own unit for figures near zero (where a share of them means nothing).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Band {
    pub share: f64,
    /// None: the share alone (a figure that is itself a share, such as a width in per cent).
    pub floor: Option<f64>,
}

impl Band {
    /// Fitted figures: ±20 %, or ±0.3 µs where the paper's is under 1.5 µs in magnitude.
    pub const FIT_US: Band = Band { share: 0.20, floor: Some(0.3) };
    /// Predicted figures: ±30 %, or ±0.5 µs.
    pub const PREDICTION_US: Band = Band { share: 0.30, floor: Some(0.5) };

    pub fn for_part(part: Part) -> Band {
        match part {
            Part::Fit => Band::FIT_US,
            Part::Prediction => Band::PREDICTION_US,
        }
    }

    /// How far from `paper` a figure may be.
    pub fn tolerance(&self, paper: f64) -> f64 {
        (self.share * paper.abs()).max(self.floor.unwrap_or(0.0))
    }
}

/// One published figure beside the model's.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figure {
    /// What the figure is, as the paper's table names it (e.g. "2 slaves, park2020, ref GMEAN").
    pub name: String,
    pub unit: &'static str,
    pub part: Part,
    pub paper: f64,
    pub model: f64,
    /// model − paper, in the figure's unit.
    pub error: f64,
    /// (model − paper) / |paper|, in per cent (None where the paper's figure is 0).
    pub error_pct: Option<f64>,
    pub band: Band,
    /// How far from the paper's figure the band reaches ([`Band::tolerance`]).
    pub tolerance: f64,
    pub within: bool,
}

impl Figure {
    pub fn new(name: impl Into<String>, unit: &'static str, part: Part, band: Band, paper: f64, model: f64) -> Self {
        let error = model - paper;
        let tolerance = band.tolerance(paper);
        Figure {
            name: name.into(),
            unit,
            part,
            paper,
            model,
            error,
            error_pct: (paper != 0.0).then(|| error / paper.abs() * 100.0),
            band,
            tolerance,
            within: error.abs() <= tolerance,
        }
    }

    /// One line for a table: name, part, paper, model, error, and whether within its band.
    pub fn line(&self) -> String {
        let pct = self.error_pct.map(|p| format!("{p:+7.1} %")).unwrap_or_else(|| format!("{:>9}", "—"));
        format!(
            "{:<34} {:<10} {:>9.2} {:>9.2} {:>+9.2} {pct}  ±{:<6.2} {}",
            self.name,
            self.part.as_str(),
            self.paper,
            self.model,
            self.error,
            self.tolerance,
            if self.within { "within" } else { "MISSES" }
        )
    }

    /// The header [`Figure::line`] goes under.
    pub fn header(unit: &str) -> String {
        format!(
            "{:<34} {:<10} {:>9} {:>9} {:>9} {:>9}  {:<7} {}",
            "figure",
            "part",
            if unit.is_empty() { "paper".to_string() } else { format!("paper {unit}") },
            "model",
            "error",
            "error %",
            "band",
            "target"
        )
    }
}

/// The names of the figures outside their bands, in order.
pub fn misses(figures: &[Figure]) -> Vec<&str> {
    figures.iter().filter(|f| !f.within).map(|f| f.name.as_str()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_take_the_larger_of_share_and_floor() {
        // 20 % of 10.58 is 2.116; 20 % of 1.06 is 0.212, so the 0.3 µs floor rules.
        assert!((Band::FIT_US.tolerance(10.58) - 2.116).abs() < 1e-9);
        assert_eq!(Band::FIT_US.tolerance(1.06), 0.3);
        assert_eq!(Band::PREDICTION_US.tolerance(-1.71), 0.513_f64.max(0.5));
        let f = Figure::new("x", "µs", Part::Prediction, Band::PREDICTION_US, -1.71, 1.0);
        assert!(!f.within && (f.error - 2.71).abs() < 1e-12);
        let g = Figure::new("y", "µs", Part::Fit, Band::FIT_US, 1.06, 1.30);
        assert!(g.within, "{g:?}");
        let w = Figure::new("width", "%", Part::Fit, Band { share: 0.2, floor: None }, 0.0, 0.1);
        assert!(!w.within && w.error_pct.is_none());
    }
}
