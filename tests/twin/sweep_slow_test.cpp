// Tests `omnitwin sweep --slurm` on a real single-node Slurm (scripts/slurm-local start: Debian's
// slurmctld, slurmd and munge on this machine, root only): the job array runs every point,
// the sweep collects them into the same table as a local run (the same metrics, point for
// point), and the batch script names one task per point. Slow: it installs and starts daemons.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>

#include "tests/twin/cli_support.hpp"

namespace omnitwin::twin::cli {
namespace {

using omnitwin::testing::lines_of;

class SweepSlurm : public CliTest {};

TEST_F(SweepSlurm, AJobArrayRunsEveryPointAndTheTableMatchesALocalRun) {
  if (::geteuid() != 0) GTEST_SKIP() << "needs root (scripts/slurm-local starts Slurm's daemons)";
  ASSERT_EQ(std::system((source_path("scripts/slurm-local") + " start").c_str()), 0);
  const std::string spec = source_path("tests/data/sweeps/short_grid.yaml");
  const fs::path slurm = dir_ / "slurm", local = dir_ / "local";
  const Finished f = run({"sweep", spec, "--slurm", "--out", slurm.string()});
  ASSERT_EQ(f.code, 0) << f.out << f.err;
  EXPECT_TRUE(contains(f.out, "4 points, 4 ran, 0 failed to run")) << f.out;
  EXPECT_TRUE(contains(read_bytes(slurm / "sweep.sbatch"), "#SBATCH --array=1-4"));
  const Finished g = run({"sweep", spec, "-j", "2", "--out", local.string()});
  ASSERT_EQ(g.code, 0) << g.out << g.err;
  // Lockstep runs are deterministic: the same metrics wherever they ran.
  EXPECT_EQ(read_bytes(slurm / "sweep.csv"), read_bytes(local / "sweep.csv"));
  EXPECT_EQ(lines_of(read_bytes(slurm / "sweep.csv")).size(), 5u);
}

}  // namespace
}  // namespace omnitwin::twin::cli
