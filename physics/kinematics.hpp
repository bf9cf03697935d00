// physics layer — kinematics of the four-omniwheel platform (seed 002, eq. 4-1 … 4-7).
//
// Pure math on Eigen fixed-size matrices, shared by the twin (to check the physics) and by
// the master program (platform loop and odometry), so it links nothing but Eigen.
//
// Sign convention (settled once, here): wheel i sits at angle alpha_i = 45°, 135°, 225°,
// 315° from X_m; its hinge axis points radially outwards and +omega_i follows the right-hand
// rule about that axis, so the hub rolls along (sin alpha_i, −cos alpha_i) in the platform
// frame. With v_i = r·omega_i this gives the thesis's D_e(phi) unchanged, including its −L
// column (a ccw turn, phidot > 0, makes every v_i negative). The thesis prints D_i's last row
// as +1/(4L)·(1,1,1,1); with the thesis's own D_e that would give D_i·D_e = diag(1,1,−1), so
// we use −1/(4L)·(1,1,1,1), the left inverse of D_e: D_i(phi)·D_e(phi) = I₃ exactly.
// Thesis check (4-4-2): moving along world +X, wheels 1 and 2 turn positive, 3 and 4 negative.
#pragma once

#include <Eigen/Core>

namespace omnitwin::physics {

using WheelVector = Eigen::Matrix<double, 4, 1>;  // v_1..v_4 [m/s] (or omega [rad/s])
using Twist = Eigen::Vector3d;                    // (Xdot_w, Ydot_w, phidot) [m/s, m/s, rad/s]
using DecouplingMatrix = Eigen::Matrix<double, 4, 3>;
using InverseMatrix = Eigen::Matrix<double, 3, 4>;

// D_e(phi), eq. 4-5: wheel rim speeds v = D_e·twist. phi [rad], L [m]. Real-time safe.
DecouplingMatrix decoupling_matrix(double phi, double L);

// D_i(phi), eq. 4-7 with the sign of the last row fixed (see above): twist = D_i·v.
// Real-time safe.
InverseMatrix inverse_matrix(double phi, double L);

// Wheel angular speeds [rad/s] for a world twist: D_e(phi)·twist / r. Real-time safe.
WheelVector wheel_speeds(const Twist& world_twist, double phi, double L, double r);

// World twist from wheel angular speeds [rad/s]: D_i(phi)·(r·omega). Real-time safe.
Twist platform_twist(const WheelVector& omega, double phi, double L, double r);

}  // namespace omnitwin::physics
