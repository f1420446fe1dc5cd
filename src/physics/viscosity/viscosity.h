#pragma once
// What the three viscosity methods share (the scene's `effects.viscosity.method`):
//   weiler2018     implicit, the Laplacian of Eq. 7 [WKBB18], CG with a block and rigid-motion preconditioner
//   explicit       the same Laplacian integrated explicitly, in sub-steps below its stable step (comparison only)
//   takahashi2015  implicit, the divergence of the SPH strain rate [TDF*15] (comparison only)
// Shared: the viscosity of each particle (one value, per fluid, or over temperature), the coefficients of Eq. 7
// and of the boundary term (Eq. 12), and the bookkeeping of a step: a later coupled pass replaces an earlier
// pass's change, the boundary's reaction goes to the bodies, and iterations and residuals go to the stats.

#include "physics/materials.h"
#include "physics/pair_sweeps.h"
#include "physics/simulation.h"

#include <functional>
#include <optional>
#include <vector>

namespace ganache {

/// Viscosity: the method and the settings of its solve.
struct ViscosityParams : EffectParams {
    /// weiler2018: the implicit solver of Weiler et al. 2018 that ganache is built on; explicit and takahashi2015
    /// are there to compare against it (ganache study).
    enum class Method { Weiler2018, Explicit, Takahashi2015 };
    Method method = Method::Weiler2018;
    std::optional<Real> mu;      ///< dynamic viscosity for every fluid [Pa s]; unset: each fluid's material
    Real boundaryMu = 0;         ///< boundary viscosity mu_b [Pa s]: 0 slips, large sticks
    /// CG stops when |r| <= tolerance |b - (I - dt A) v|, the residual relative to the correction the solve has to
    /// make. The rigid motions are solved exactly after CG, so the tolerance does not decide what happens to momentum
    /// or spin. Where the fluid is soft it mostly decides how much extra the constant-density solve does after
    /// viscosity: at 1e-2 a viscous column at rest stays within the DFSPH tolerance (mean compression 6.5e-5, at 1e-3
    /// 2.7e-6; test PressureDFSPH.ViscousColumnRestsToTheSolverTolerance), and the anchors' spread errors against a
    /// converged reference are 0.09 / 1.0 / 0.2 % (at 1e-3 0.09 / 1.4 / 0.08 %; SPlisHSPlasH's 0.9 / 10 / 0.9 %)
    /// with half the CG iterations (docs/benchmarks.md).
    Real tolerance = 1e-2;
    /// The tolerance of solves with stiff particles (stiffness dt mu / (rho h^2) from 3,000, where the clusters
    /// join the preconditioner) or with viscosities that differ between particles, when it is the smaller: there it
    /// decides how stiff the fluid stays (a 5e6 Pa s body on a slipping floor kept parts moving at 3.7 cm/s at 1e-2,
    /// 0.55 cm/s at 1e-3, with the clusters) and whether the runny particles beside stiffer ones move as they should.
    Real stiffTolerance = 1e-3;
    std::int64_t maxIterations = 100;  ///< CG iterations per solve; explicit: sub-steps per step (default 10,000)
    /// none, 3x3 block Jacobi, or block Jacobi plus a coarse space (two-level, weiler2018 only): the rigid motions of
    /// the whole fluid, or of each cluster of nearby particles (weiler2018's default; takahashi2015 defaults to
    /// block Jacobi)
    enum class Preconditioner { None, BlockJacobi, Rigid, Clusters };
    Preconditioner preconditioner = Preconditioner::Clusters;
    bool warmStart = true;       ///< initial guess v_df + dv of the previous step (false: v_df)
    /// Eq. 7's pair weights (weiler2018 and explicit). paper: 2(d+2) times the kernel gradient, whose sum over the
    /// sampling lattice gives 0.70 of the Laplacian for shear along the lattice's axes and 1.43 across a face
    /// diagonal (plane Couette flow lagged 4.7 %); lattice (the default): each pair's weight reshaped by a quadratic
    /// in |x_ij|^2 so that the lattice's fourth moments are those of a continuum, and scaled to be exact there: the
    /// same Laplacian in every direction, on the lattice and in a disordered fluid alike (Couette within 0.7 %).
    enum class Laplacian { Lattice, Paper };
    Laplacian laplacian = Laplacian::Lattice;
};

/// The weight Eq. 7 gives a pair at squared distance d2, relative to the paper's 2(d+2) grad W / (d2 + 0.01 h^2): a
/// constant scale and, for Laplacian::Lattice, a shape in d2 / s^2 (s the sampling spacing, two particle radii).
class LaplacianWeights {
public:
    LaplacianWeights(ViscosityParams::Laplacian kind, Real spacing, const CubicSpline& kernel);
    Real scale() const { return m_scale; }
    Real shape(Real d2) const {
        const Real u = d2 * m_inverseSpacing2 - 1;
        return 1 + u * (linear() + u * quadratic());  // the sweeps take the same coefficients
    }
    Real inverseSpacing2() const { return m_inverseSpacing2; }
    /// The shape's coefficients: 0 for the paper's weights.
    Real linear() const { return m_reshaped ? kShapeLinear : 0; }
    Real quadratic() const { return m_reshaped ? kShapeQuadratic : 0; }

    // 1 + a u + b u^2 with u = d2 / s^2 - 1: the two conditions on (a, b) are that the lattice's sums of the
    // pairs' weights times x^4 and times 3 x^2 y^2 agree (no preferred shear direction) and that the lattice's sum
    // equals the continuum's integral of the same weights (the same Laplacian in a disordered fluid). Solved by
    // Newton's method for the cubic spline with support two spacings; u is 0, 1 and 2 on the three shells inside.
    static constexpr Real kShapeLinear = 0.10542625248565, kShapeQuadratic = 0.84021970770464;

private:
    bool m_reshaped;
    Real m_inverseSpacing2;
    Real m_scale;
};

/// Reads `effects.viscosity`.
std::shared_ptr<const EffectParams> readViscosity(Section& s);
/// The method the parameters name.
std::unique_ptr<Effect> makeViscosity(const EffectParams& params, const SimulationSetup& setup, ParticleSet& particles);

/// mu of every fluid particle [Pa s]: one value for the scene, or (when the sources differ or melt) each
/// particle's own, kept in the attribute `viscosity`.
class ParticleViscosity {
public:
    ParticleViscosity(const ViscosityParams& params, const SimulationSetup& setup, ParticleSet& particles);
    /// Recomputes each particle's viscosity from its source and temperature; nothing when it is one value.
    void refresh(const ParticleSet& particles);
    Real operator()(std::size_t i) const { return m_perParticle ? (*m_perParticle)[i] : m_mu; }
    /// Whether particles differ in viscosity.
    bool varies() const { return m_perParticle != nullptr; }
    /// Each particle's viscosity, or null when they share one.
    const Real* values() const { return m_perParticle ? m_perParticle->data() : nullptr; }

private:
    Real m_mu = 0;
    std::vector<Real>* m_perParticle = nullptr;            // attribute::kViscosity, only when viscosities differ
    std::vector<Real> m_sourceMu;                          // mu of each fluid and emitter, when viscosity varies
    std::vector<std::optional<ViscosityLaw>> m_sourceLaw;  // their laws over temperature, with the heat effect
};

/// Iterations (or explicit sub-steps) and relative residual of one viscosity pass.
struct ViscosityPass {
    std::size_t iterations = 0;
    Real residual = 0;
    Real tolerance = 0;  ///< the relative residual it aimed at
};

/// Dot product of two vector fields; deterministic, so every run takes the same CG iterations.
Real fieldDot(const std::vector<Vec3>& a, const std::vector<Vec3>& b);

/// Preconditioned conjugate gradients for a symmetric positive definite system M x = b, with M and the
/// preconditioner P given as functions and the vectors kept between solves. Each function also returns the dot
/// product of its input and output, which it can take in the same pass (deterministically: see fieldDot).
struct ConjugateGradient {
    /// out = M in (or z = P r); returns in . out.
    using Apply = std::function<Real(const std::vector<Vec3>& in, std::vector<Vec3>& out)>;
    std::vector<Vec3> r, z, p, q;
    Real scale = 0;  ///< |b - M v| of the last solve: the correction the solve had to make
    /// `x` holds the initial guess; iterates until |r| <= tolerance |b - M v| (the residual relative to the
    /// correction the solve has to make from the velocities v before it, not to |b|: at small dt that correction
    /// is a tiny fraction of the velocity, and a |b|-relative test let a warm-started guess pass untouched step
    /// after step, 0.1 CG iterations per solve at dt = 0.05 ms) or maxIterations. When v already solves the
    /// system (scale 0) x becomes v. On return `r` holds the residual b - M x.
    ViscosityPass solve(const Apply& multiply, const Apply& precondition, const std::vector<Vec3>& b,
                        const std::vector<Vec3>& v, std::vector<Vec3>& x, Real tolerance, std::size_t maxIterations);
    /// What solve() does before its iterations: sizes the vectors, sets `scale`, r = b - M x and `pass`; false where
    /// no iteration is needed (x = v where scale is 0). For solvers that run their own iterations on these vectors.
    bool start(const std::vector<Vec3>& b, const std::vector<Vec3>& v, const std::vector<Vec3>& mv,
               const std::vector<Vec3>& mx, std::vector<Vec3>& x, Real tolerance, std::size_t maxIterations,
               ViscosityPass& pass);
};

/// The initial guess x = v + a d1 + c d2 with the least energy x.Mx / 2 - b.x over a and c (M symmetric positive
/// definite), from the products mv = M v, md1 = M d1 and md2 = M d2; writes x and mx = M x. Its set holds v itself and
/// every fixed extrapolation from d1 and d2, so in M's norm it lies no further from the solution than any of them.
/// Where d2 is (nearly) parallel to d1, or zero, c is 0.
void leastEnergyGuess(const std::vector<Vec3>& b, const std::vector<Vec3>& v, const std::vector<Vec3>& mv,
                      const std::vector<Vec3>& d1, const std::vector<Vec3>& md1, const std::vector<Vec3>& d2,
                      const std::vector<Vec3>& md2, std::vector<Vec3>& x, std::vector<Vec3>& mx);

/// What leastEnergyGuess decides on, summed over the particles: d1.Md1, d1.Md2, d2.Md2, d1.(b - Mv), d2.(b - Mv).
using GuessSums = Eigen::Matrix<Real, 5, 1>;
/// Particle i's share of GuessSums, for a pass that has its products at hand.
inline GuessSums guessTerms(const Vec3& b, const Vec3& mv, const Vec3& d1, const Vec3& md1, const Vec3& d2,
                            const Vec3& md2) {
    const Vec3 r = b - mv;
    return GuessSums(d1.dot(md1), d1.dot(md2), d2.dot(md2), d1.dot(r), d2.dot(r));
}
/// leastEnergyGuess from its sums, taken beforehand.
void leastEnergyGuess(const GuessSums& sums, const std::vector<Vec3>& v, const std::vector<Vec3>& mv,
                      const std::vector<Vec3>& d1, const std::vector<Vec3>& md1, const std::vector<Vec3>& d2,
                      const std::vector<Vec3>& md2, std::vector<Vec3>& x, std::vector<Vec3>& mx);

/// A viscosity method as an effect. apply() takes back an earlier coupled pass's change, asks the method for the
/// new velocities, and records the change, the boundary loads and the statistics.
class ViscosityMethod : public Effect {
public:
    ViscosityMethod(const ViscosityParams& params, const SimulationSetup& setup, ParticleSet& particles);
    void apply(StepContext& ctx, ParticleSet& particles) final;
    /// solves, iterations_per_solve (CG; explicit: sub-steps), cap_hits, worst_residual
    std::vector<Counter> counters(std::size_t steps) const override;
    void save(ByteWriter& out) const override;
    void restore(ByteReader& in) override;

    /// Iterations and relative residual of the last pass.
    std::size_t lastIterations() const { return m_last.iterations; }
    Real lastResidual() const { return m_last.residual; }

protected:
    /// Writes the velocities after viscosity into `out`, which holds the initial guess on entry (the current
    /// velocity v, or v plus the previous change with the warm start); v itself is particles.v().
    virtual ViscosityPass solve(StepContext& ctx, const ParticleSet& particles, std::vector<Vec3>& out) = 0;
    /// The warning of a pass that ended above the tolerance.
    virtual std::string capMessage(const StepContext& ctx, const ViscosityPass& pass) const;

    /// Eq. 7's coefficient of each pair with its kernel gradient factor, at the step's positions, densities and
    /// viscosities: k_ij = 2(d+2) mu_ij m_ij / (rho_i rho_j (|x_ij|^2 + 0.01 h^2)) g_ij (mu and m averaged over the
    /// pair, so the operator is symmetric [Eq. 9]; grad W_ij = g_ij x_ij), in the order of the fluid neighbour
    /// lists; with boundary viscosity, k_ik = 2(d+2) mu_b Psi_k / (rho_i^2 (|x_ik|^2 + 0.01 h^2)) g_ik [Eq. 11-12].
    /// apply() computes them before solve(), so no product evaluates them again.
    /// Stored in single precision (sweeps::PairWeight); fluidBlock() is summed from the stored values, so the blocks
    /// are those of the operator the products apply.
    const sweeps::PairWeights& pairs() const { return m_pairs; }
    const std::vector<Real>& boundaryPairs() const { return m_boundaryPairs; }
    /// sum_j k_ij x_ij x_ij^T: the fluid's part of particle i's diagonal block of A (computed with pairs()).
    const Mat3& fluidBlock(std::size_t i) const { return m_fluidBlocks[i]; }
    bool sticky() const { return m_params.boundaryMu > 0; }
    /// On the first pass of a step with the warm start: the changes of velocity of the last step and of the one
    /// before it, from which solve()'s initial guess is extrapolated and which a method may combine better; null on
    /// other passes.
    const std::vector<Vec3>* lastChange() const { return m_warmPass ? m_dv : nullptr; }
    const std::vector<Vec3>* earlierChange() const { return m_warmPass ? m_earlierDv : nullptr; }
    /// The boundary's share of particle i's implicit system [Eq. 11-12]: returns sum_k c_ik grad W_ik x_ik^T (the
    /// operator's diagonal block, per unit mass) and adds sum_k c_ik (v_k . x_ik) grad W_ik, the bodies'
    /// velocities, to `bodyTerm`.
    Mat3 boundaryBlock(const StepContext& ctx, const ParticleSet& particles, std::size_t i, Vec3& bodyTerm) const;
    /// The viscous acceleration of Eq. 7 at particle i for the velocity field `in` [m/s^2]:
    /// sum_j c_ij (x_ij . (in_i - in_j)) grad W_ij, plus, with boundary viscosity, the boundary's
    /// sum_k c_ik (x_ik . (in_i - v_k)) grad W_ik, where the bodies' own velocities v_k count only when
    /// withBodyVelocity (an implicit solve moves them to its right-hand side).
    Vec3 laplacian(const StepContext& ctx, const ParticleSet& particles, const std::vector<Vec3>& in, std::size_t i,
                   bool withBodyVelocity) const;

    const ViscosityParams m_params;
    ParticleViscosity m_mu;

private:
    void addBoundaryLoads(StepContext& ctx, const ParticleSet& particles, bool firstPass);
    void computeCoefficients(const StepContext& ctx, const ParticleSet& particles);

    LaplacianWeights m_weights;
    std::vector<Vec3>* m_dv;  // the last pass's change, a particle attribute (kChange in viscosity.cpp)
    std::vector<Vec3> m_out;
    sweeps::PairWeights m_pairs;  // see pairs()
    std::vector<Real> m_boundaryPairs;
    std::vector<Mat3> m_fluidBlocks;
    std::vector<Real> m_inverseDensity;  // 1 / rho_i of the step, from apply()
    std::vector<Vec3> m_wallImpulse;  // per particle, the bodies' share of its viscous change (addBoundaryLoads)
    BodyLoads m_passLoads;    // the viscous loads of the latest pass, which a later pass of the step replaces
    std::size_t m_lastStep = 0;
    Real m_lastDt = 0, m_earlierDt = 0;  // the last two steps: scale the warm start
    std::vector<Vec3>* m_earlierDv;       // the change of the step before the last (kEarlierChange)
    bool m_hasSolved = false;
    bool m_warmPass = false;  // this pass is a step's first, with the warm start
    ViscosityPass m_last;
    // Over the run:
    std::size_t m_solves = 0, m_iterations = 0, m_capHits = 0;
    Real m_worstResidual = 0;  // the largest relative residual a solve ended with
};

}  // namespace ganache
