//! What the grid models ([`DenseGrid`](crate::dense::DenseGrid) and
//! [`SparseGrid`](crate::sparse::SparseGrid)) share: a render and a training loss that are the
//! shading of one parameter's values looked up at the samples, over the environment if the
//! model has one, plus a prior on those values. The models differ only in the lookup and the
//! prior, which each gives here.

use fogray_ops::rays::RayBatch;
use fogray_ops::sample::PackedSamples;
use fogray_ops::CompositeVars;
use fogray_tape::params::{ParamId, Params};
use fogray_tape::{Float, Tape, TapeError, Var};

use crate::environment::environment_on_tape;
use crate::model::{RenderWanted, TrainingBackground, TrainingLoss};
use crate::settings::Method;
use crate::shading::Shading;

/// A model whose field is one parameter's values looked up at each sample, then shaded.
pub(crate) trait GridModel<F: Float> {
    /// The parameters, and which of them the lookup reads.
    fn values(&self) -> (&Params<F>, ParamId);
    /// How the looked-up values become densities and colours.
    fn shading(&self) -> &Shading;
    /// The distortion loss's weight in the training loss (0 for none).
    fn distortion(&self) -> f64;
    /// Records the lookup of `values` (on the tape) at `positions`.
    fn lookup(&self, tape: &mut Tape<F>, values: Var, positions: Var, method: Method) -> Result<Var, TapeError>;
    /// Records the prior on `values`, if it has a weight.
    fn prior(&self, tape: &mut Tape<F>, values: Var) -> Result<Option<Var>, TapeError>;

    /// [`RadianceField::render`](crate::model::RadianceField::render) of such a model.
    fn render_grid(
        &self,
        tape: &mut Tape<F>,
        rays: &RayBatch<F>,
        samples: PackedSamples<F>,
        background: [f64; 3],
        method: Method,
        wanted: RenderWanted,
    ) -> Result<CompositeVars, TapeError> {
        let (params, id) = self.values();
        let values = tape.param_from(params, id)?;
        let environment = environment_on_tape(tape, params)?;
        let shaded = self.shading().composite_inputs(
            tape,
            rays,
            samples,
            TrainingBackground::Shared(background),
            environment,
            method,
            wanted.depth,
            0.0,
            |tape, positions| self.lookup(tape, values, positions, method),
        )?;
        shaded.render(tape, method)
    }

    /// [`RadianceField::training_loss`](crate::model::RadianceField::training_loss) of such a
    /// model: the shaded composite's loss, with the distortion loss and the prior.
    fn training_loss_grid(
        &self,
        tape: &mut Tape<F>,
        rays: &RayBatch<F>,
        samples: PackedSamples<F>,
        background: TrainingBackground<F>,
        target: Var,
        method: Method,
    ) -> Result<TrainingLoss, TapeError> {
        let (params, id) = self.values();
        let values = tape.param_from(params, id)?;
        let environment = environment_on_tape(tape, params)?;
        let shaded = self.shading().composite_inputs(
            tape,
            rays,
            samples,
            background,
            environment,
            method,
            false,
            self.distortion(),
            |tape, positions| self.lookup(tape, values, positions, method),
        )?;
        let prior = self.prior(tape, values)?;
        shaded.training_loss(tape, target, method, prior)
    }
}
