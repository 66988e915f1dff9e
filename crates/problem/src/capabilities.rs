//! What a stepper can do, as a set the facade checks a scene against in one place.

use std::fmt;

/// One thing a scene may need from its stepper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Capability {
    /// Contact with a static mesh (a vessel), with friction.
    MeshContact,
    /// A straight introducer the rod is fed through.
    Guide,
    /// A rod bound inside another (guidewire in a catheter).
    Bindings,
    /// Rod–rod and self-contact.
    RodContact,
    /// The stiff (implicit) scheme.
    StiffScheme,
    /// The explicit scheme with exact (direct) distance constraints.
    DirectConstraints,
    /// The force and torque at held ends.
    Reactions,
    /// Double precision.
    DoublePrecision,
    /// Held ends driven along keyframed paths ([`crate::EndPath`]).
    EndPaths,
    /// Held end points that slide along an axis.
    SlidingEnds,
    /// Clamps that turn freely about an axis (hinges).
    HingedEnds,
    /// Loads varying in time.
    VaryingLoads,
    /// Point moments.
    Moments,
    /// Several obstacles, obstacles of different friction, or analytic shapes (half-spaces,
    /// infinite cylinders).
    Obstacles,
    /// Obstacles moving along keyframed paths.
    MovingObstacles,
}

impl Capability {
    /// Every capability, in a fixed order.
    pub const ALL: [Capability; 15] = [
        Capability::MeshContact,
        Capability::Guide,
        Capability::Bindings,
        Capability::RodContact,
        Capability::StiffScheme,
        Capability::DirectConstraints,
        Capability::Reactions,
        Capability::DoublePrecision,
        Capability::EndPaths,
        Capability::SlidingEnds,
        Capability::HingedEnds,
        Capability::VaryingLoads,
        Capability::Moments,
        Capability::Obstacles,
        Capability::MovingObstacles,
    ];

    fn bit(self) -> u32 {
        1 << (self as u32)
    }

    /// How the capability is named in errors and reports.
    pub fn describe(self) -> &'static str {
        match self {
            Capability::MeshContact => "mesh contact ([environment])",
            Capability::Guide => "an introducer guide",
            Capability::Bindings => "bindings ([[binding]])",
            Capability::RodContact => "rod–rod contact and self-contact ([rod_contact])",
            Capability::StiffScheme => "the stiff scheme (solver.scheme = \"stiff\")",
            Capability::DirectConstraints => {
                "direct distance constraints (solver.constraint_solver = \"direct\")"
            }
            Capability::Reactions => "reaction forces at held ends",
            Capability::DoublePrecision => "f64 (solver.precision = \"f64\")",
            Capability::EndPaths => "keyframed end paths (rod.start.path / rod.end.path)",
            Capability::SlidingEnds => "sliding ends (rod.start.slide / rod.end.slide)",
            Capability::HingedEnds => "hinged clamps (rod.start.hinge / rod.end.hinge)",
            Capability::VaryingLoads => "time-varying loads ([[rod.load]] profile)",
            Capability::Moments => "point moments ([[rod.load]] moment)",
            Capability::Obstacles => {
                "several obstacles or analytic shapes ([[obstacles]]: half-spaces, infinite cylinders, meshes of their own friction)"
            }
            Capability::MovingObstacles => "moving obstacles ([[obstacles]] path)",
        }
    }
}

impl fmt::Display for Capability {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.describe())
    }
}

/// A set of [`Capability`] values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Capabilities(u32);

impl Capabilities {
    /// The empty set.
    pub const NONE: Capabilities = Capabilities(0);

    /// The set of the given capabilities.
    pub fn of(list: &[Capability]) -> Self {
        list.iter().fold(Self::NONE, |s, &c| s.with(c))
    }

    /// This set and `c`.
    #[must_use]
    pub fn with(self, c: Capability) -> Self {
        Self(self.0 | c.bit())
    }

    /// This set and every capability of `other`.
    #[must_use]
    pub fn union(self, other: Capabilities) -> Self {
        Self(self.0 | other.0)
    }

    /// This set and `c` when `yes`.
    #[must_use]
    pub fn with_if(self, c: Capability, yes: bool) -> Self {
        if yes { self.with(c) } else { self }
    }

    /// Whether `c` is in the set.
    pub fn contains(self, c: Capability) -> bool {
        self.0 & c.bit() != 0
    }

    /// The capabilities of `needs` that this set lacks, in [`Capability::ALL`] order.
    pub fn missing(self, needs: Capabilities) -> Vec<Capability> {
        Capability::ALL
            .into_iter()
            .filter(|&c| needs.contains(c) && !self.contains(c))
            .collect()
    }

    /// The capabilities in the set, in [`Capability::ALL`] order.
    pub fn iter(self) -> impl Iterator<Item = Capability> {
        Capability::ALL
            .into_iter()
            .filter(move |&c| self.contains(c))
    }
}

#[cfg(test)]
mod tests {
    use super::{Capabilities, Capability};

    #[test]
    fn missing_lists_exactly_what_the_needs_ask_beyond_the_set() {
        let have = Capabilities::of(&[Capability::MeshContact, Capability::Reactions]);
        let needs = Capabilities::of(&[
            Capability::MeshContact,
            Capability::Guide,
            Capability::DoublePrecision,
        ]);
        assert_eq!(
            have.missing(needs),
            vec![Capability::Guide, Capability::DoublePrecision]
        );
        assert!(needs.missing(Capabilities::NONE).is_empty());
        assert_eq!(have.iter().count(), 2);
        assert!(
            !have
                .with_if(Capability::Guide, false)
                .contains(Capability::Guide)
        );
    }
}
