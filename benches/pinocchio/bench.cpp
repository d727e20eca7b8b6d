// Pinocchio's aba, rnea and joint-torque regressor timed on given states: the C++ half of
// benches/pinocchio_compare.py, which builds this file against the `pin` wheel's headers and
// libraries and runs it beside didim's own timing binary on the same URDF and the same states.
//
// bench URDF STATES OUT ROUNDS [JOINT,JOINT,...]
//   STATES: "n K", then K rows of q, K of v, K of a, K of tau (n values each), then the armature
//           (n values: aba's only)
//   OUT:    per state, aba's n values, rnea's n, the regressor's n x 10n (row-major), one per line
//   prints: "<algorithm> <best ns per call> <median ns per call>" for aba, rnea, regressor
// With joints given, the others are locked at zero (pinocchio::buildReducedModel), as didim does.
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/model.hpp>
#include <pinocchio/algorithm/regressor.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/parsers/urdf.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

using Vec = Eigen::VectorXd;

static std::vector<Vec> read_rows(std::istream & in, int rows, int n)
{
  std::vector<Vec> out(rows, Vec(n));
  for (auto & r : out)
    for (int j = 0; j < n; ++j)
      in >> r[j];
  return out;
}

int main(int argc, char ** argv)
{
  if (argc < 5)
  {
    std::cerr << "usage: bench URDF STATES OUT ROUNDS [JOINT,JOINT,...]\n";
    return 2;
  }
  pinocchio::Model full;
  pinocchio::urdf::buildModel(argv[1], full);
  pinocchio::Model model = full;
  if (argc > 5)
  {
    std::vector<std::string> keep;
    std::stringstream ss(argv[5]);
    for (std::string name; std::getline(ss, name, ',');)
      keep.push_back(name);
    std::vector<pinocchio::JointIndex> lock;
    for (pinocchio::JointIndex j = 1; j < (pinocchio::JointIndex)full.njoints; ++j)
      if (std::find(keep.begin(), keep.end(), full.names[j]) == keep.end())
        lock.push_back(j);
    model = pinocchio::buildReducedModel(full, lock, pinocchio::neutral(full));
  }
  std::ifstream in(argv[2]);
  int n, k;
  in >> n >> k;
  if (!in || n != model.nv || model.nq != model.nv)
  {
    std::cerr << "the states have " << n << " joints, the model " << model.nv << "\n";
    return 2;
  }
  const auto q = read_rows(in, k, n), v = read_rows(in, k, n), a = read_rows(in, k, n),
             tau = read_rows(in, k, n);
  Vec armature(n);
  for (int j = 0; j < n; ++j)
    in >> armature[j];
  if (!in)
  {
    std::cerr << "could not read the states\n";
    return 2;
  }
  // aba with the armature (added to each joint's articulated inertia), as didim's aba is given it;
  // rnea and the regressor without (Pinocchio's rnea adds armature * a, didim's has no armature)
  pinocchio::Model with_armature = model;
  with_armature.armature = armature;
  pinocchio::Data data(model);
  const int rounds = std::stoi(argv[4]);

  // the results, for the driver's check against didim's
  {
    std::FILE * out = std::fopen(argv[3], "w");
    for (int s = 0; s < k; ++s)
    {
      const Vec & ddq = pinocchio::aba(with_armature, data, q[s], v[s], tau[s]);
      for (int j = 0; j < n; ++j)
        std::fprintf(out, "%.17g ", ddq[j]);
      const Vec & t = pinocchio::rnea(model, data, q[s], v[s], a[s]);
      for (int j = 0; j < n; ++j)
        std::fprintf(out, "%.17g ", t[j]);
      const auto & y = pinocchio::computeJointTorqueRegressor(model, data, q[s], v[s], a[s]);
      for (int r = 0; r < y.rows(); ++r)
        for (int c = 0; c < y.cols(); ++c)
          std::fprintf(out, "%.17g ", y(r, c));
      std::fprintf(out, "\n");
    }
    std::fclose(out);
  }

  // each round times each algorithm once over the K states (ns per call); the rounds alternate
  // the algorithms so that a slow spell of the machine falls on all three
  using clock = std::chrono::steady_clock;
  double sink = 0.0;
  std::vector<double> t_aba, t_rnea, t_reg;
  auto time = [&](auto && f) {
    const auto t0 = clock::now();
    for (int s = 0; s < k; ++s)
      sink += f(s);
    return std::chrono::duration<double, std::nano>(clock::now() - t0).count() / k;
  };
  for (int r = 0; r < rounds; ++r)
  {
    t_aba.push_back(
      time([&](int s) { return pinocchio::aba(with_armature, data, q[s], v[s], tau[s])[0]; }));
    t_rnea.push_back(
      time([&](int s) { return pinocchio::rnea(model, data, q[s], v[s], a[s])[0]; }));
    t_reg.push_back(time([&](int s) {
      return pinocchio::computeJointTorqueRegressor(model, data, q[s], v[s], a[s])(0, 0);
    }));
  }
  auto report = [](const char * name, std::vector<double> t) {
    std::sort(t.begin(), t.end());
    std::printf("%s %.2f %.2f\n", name, t.front(), t[t.size() / 2]);
  };
  report("aba", t_aba);
  report("rnea", t_rnea);
  report("regressor", t_reg);
  std::fprintf(stderr, "checksum %g\n", sink);
  return 0;
}
