// Pinocchio's aba, rnea and joint-torque regressor timed on given states: the C++ half of
// benches/pinocchio_compare.py, which builds this file against the `pin` wheel's headers and
// runs it beside didim's own timing binary on the same robot and the same states.
//
// bench MODEL STATES OUT ROUNDS
//   MODEL:  the model that pin's URDF parser built (the driver writes it from Python): the number
//           of joints, then per joint its type (RX RY RZ RU PX PY PZ PU), parent, axis (3), placement
//           rotation (9, row-major) and translation (3), mass, centre of mass (3) and inertia about
//           it (Ixx Ixy Iyy Ixz Iyz Izz). Rebuilt here with Model::addJoint and appendBodyToJoint,
//           all in this file (header-only): the wheel's compiled parser hands over a Model whose
//           layout is not this -march=native build's.
//   STATES: "n K", then K rows of q, K of v, K of a, K of tau (n values each), then the armature
//           (n values: aba's only)
//   OUT:    per state, aba's n values, rnea's n, the regressor's n x 10n (row-major), one per line
//   prints: "<algorithm> <best ns per call> <median ns per call>" for aba, rnea, regressor
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/regressor.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
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

static bool read_model(const char * path, pinocchio::Model & model)
{
  using namespace pinocchio;
  std::ifstream in(path);
  int joints;
  in >> joints;
  for (int i = 1; i <= joints && in; ++i)
  {
    std::string type;
    int parent;
    Eigen::Vector3d axis, p, com;
    Eigen::Matrix3d r;
    double mass, ixx, ixy, iyy, ixz, iyz, izz;
    in >> type >> parent >> axis[0] >> axis[1] >> axis[2];
    for (int k = 0; k < 9; ++k)
      in >> r(k / 3, k % 3);
    in >> p[0] >> p[1] >> p[2] >> mass >> com[0] >> com[1] >> com[2] >> ixx >> ixy >> iyy >> ixz
      >> iyz >> izz;
    const SE3 placement(r, p);
    const std::string name = "joint" + std::to_string(i);
    JointIndex id;
    if (type == "RX")
      id = model.addJoint(parent, JointModelRX(), placement, name);
    else if (type == "RY")
      id = model.addJoint(parent, JointModelRY(), placement, name);
    else if (type == "RZ")
      id = model.addJoint(parent, JointModelRZ(), placement, name);
    else if (type == "RU")
      id = model.addJoint(parent, JointModelRevoluteUnaligned(axis), placement, name);
    else if (type == "PX")
      id = model.addJoint(parent, JointModelPX(), placement, name);
    else if (type == "PY")
      id = model.addJoint(parent, JointModelPY(), placement, name);
    else if (type == "PZ")
      id = model.addJoint(parent, JointModelPZ(), placement, name);
    else if (type == "PU")
      id = model.addJoint(parent, JointModelPrismaticUnaligned(axis), placement, name);
    else
    {
      std::cerr << "joint type " << type << " is not one this benchmark builds\n";
      return false;
    }
    model.appendBodyToJoint(
      id, Inertia(mass, com, Symmetric3(ixx, ixy, iyy, ixz, iyz, izz)), SE3::Identity());
  }
  return bool(in);
}

int main(int argc, char ** argv)
{
  if (argc < 5)
  {
    std::cerr << "usage: bench MODEL STATES OUT ROUNDS\n";
    return 2;
  }
  pinocchio::Model model;
  if (!read_model(argv[1], model))
  {
    std::cerr << "could not read the model\n";
    return 2;
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
